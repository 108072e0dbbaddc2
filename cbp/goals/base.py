# SPDX-License-Identifier: Apache-2.0
"""What every goal source is: the protocol a run samples, and a scenario's kinds' base.

A run samples a :class:`GoalSource` at its rate, whatever it is: a scenario's
stream of one of the kinds in :data:`cbp.goals.GOAL_KINDS`, or an operator's
live goal. A kind is a :class:`GoalStream` subclass with a ``type_name`` and the
schema of its ``goal:`` section, a :class:`GoalSpec` subclass.
"""

from __future__ import annotations

import abc
import bisect
import builtins
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.robot import FloatArray

__all__ = [
    "TIME_TOLERANCE",
    "GoalSource",
    "GoalSpec",
    "GoalStream",
    "LiveGoalSource",
    "PoseTrack",
]

#: Times closer than this to a keyframe or sample are on it [s] (recordings are
#: written with microsecond precision).
TIME_TOLERANCE = 1e-6


class GoalSource(Protocol):
    """What a run samples the operator's goal from.

    A scenario's stream (:class:`GoalStream`), or a live source such as the
    teleoperation page's (:class:`cbp.goals.LiveGoal`); a run's parts take
    any (:func:`cbp.run.build_run`'s ``goal``).
    """

    @property
    def rate_hz(self) -> float:
        """Rate at which the goal is sampled and sent [Hz]."""
        ...

    def sample(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Goal position (3,) [m] and rotation (3, 3) at time ``t`` [s], world frame."""
        ...


@runtime_checkable
class LiveGoalSource(GoalSource, Protocol):
    """A goal source an operator moves while the run goes on (the teleop page's).

    A planner that works through a period may take a newer goal between its
    steps (:meth:`cbp.run.GoalInput.changed`); a scenario's stream has none.
    """

    def changed(self) -> bool:
        """Whether a goal newer than the last one sampled has arrived."""
        ...


@dataclass(frozen=True, kw_only=True)
class GoalSpec:
    """The ``goal:`` section of a scenario; ``type:`` names its kind.

    Each kind of :data:`cbp.goals.GOAL_KINDS` adds its own keys (sections
    below); the section is read as the kind its ``type`` names.
    """

    type: str
    """The kind of goal: a name of :data:`cbp.goals.GOAL_KINDS`."""
    task: str | None = None
    """Name of the task entry that receives the goal (default: the first
    ``goal_pose`` task)."""
    rate_hz: float = 30.0
    """Rate at which the goal is sampled and sent [Hz]."""

    @classmethod
    def variants(cls) -> Mapping[str, builtins.type[GoalSpec]]:
        """Each kind's section schema, by type name (what the schema reads)."""
        from cbp.goals import GOAL_KINDS

        return {name: kind.Spec for name, kind in GOAL_KINDS.items()}

    def __post_init__(self) -> None:
        """A rate of at most 1 kHz; the section is its kind's schema."""
        if not 0 < self.rate_hz <= 1000.0:
            raise ConfigError(f"must be in (0, 1000] Hz, got {self.rate_hz}", "rate_hz")
        variants = self.variants()
        kind = variants.get(self.type)
        if kind is not type(self):
            raise ConfigError(
                f"{type(self).__name__} is not the section of a {self.type!r} goal"
                + (
                    f" ({kind.__name__} is)"
                    if kind is not None
                    else f"; kinds: {', '.join(variants)}"
                ),
                "type",
            )


class GoalStream(abc.ABC):
    """A scenario's goal source of one kind (a row of :data:`cbp.goals.GOAL_KINDS`).

    Built per run from the scenario's section; sampled like an operator's
    input device, at :attr:`rate_hz`.

    Args:
        spec: the ``goal:`` section, of this kind's :attr:`Spec`.
        folder: where files the section names are found (the scenario's).

    Raises:
        ConfigError: the section cannot be sampled (location in the section);
            a :class:`~cbp.errors.DataFileError` for a file it names.
    """

    #: The ``type:`` that names this kind in a scenario.
    type_name: ClassVar[str]
    #: The schema of this kind's ``goal:`` section.
    Spec: ClassVar[type[GoalSpec]]

    def __init__(self, spec: GoalSpec, folder: Path | None = None) -> None:
        """Keep the section; a kind reads or compiles what it needs."""
        del folder
        self.spec = spec
        self.period = 1.0 / spec.rate_hz

    @property
    def rate_hz(self) -> float:
        """Rate at which the goal is sampled and sent [Hz]."""
        return self.spec.rate_hz

    @property
    def end_time(self) -> float:
        """Time of the last keyframe or sample (0 for a function) [s]."""
        return 0.0

    @abc.abstractmethod
    def sample(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Goal position (3,) [m] and rotation (3, 3) at time ``t`` [s], world frame."""

    def pose(self, t: float) -> pin.SE3:
        """The goal at time ``t`` as an SE3."""
        position, rotation = self.sample(t)
        return pin.SE3(rotation, position)

    def problems(self, duration: float) -> list[ConfigError]:
        """What fails only over a run of ``duration`` [s] (located in the section).

        The loader asks before the run; a kind whose goal is valid at every
        time says nothing.
        """
        del duration
        return []


class PoseTrack:
    """Poses at increasing times, sampled between them (slerp) or held.

    Args:
        times: increasing times [s].
        positions: a position (3,) [m] per time.
        rotations: a rotation (3, 3) per time.
        hold: each pose held from its time on (a jump) instead of interpolated.
    """

    def __init__(
        self,
        times: Sequence[float],
        positions: Sequence[FloatArray],
        rotations: Sequence[FloatArray],
        hold: bool = False,
    ) -> None:
        """Keep the poses (at least one)."""
        if not times:
            raise ValueError("a pose track needs at least one pose")
        self.times = list(times)
        self.positions = list(positions)
        self.rotations = list(rotations)
        self.hold = hold

    def at(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Position (3,) and rotation (3, 3) at ``t`` [s].

        Held before the first and after the last pose.
        """
        i = bisect.bisect_right(self.times, t)
        if i == 0:
            return self.positions[0], self.rotations[0]
        if i == len(self.times) or self.hold:
            return self.positions[i - 1], self.rotations[i - 1]
        t0, t1 = self.times[i - 1], self.times[i]
        if t - t0 < TIME_TOLERANCE:  # on a sample (within the file's precision)
            return self.positions[i - 1], self.rotations[i - 1]
        if t1 - t < TIME_TOLERANCE:
            return self.positions[i], self.rotations[i]
        s = (t - t0) / (t1 - t0)
        p0, p1 = self.positions[i - 1], self.positions[i]
        R0, R1 = self.rotations[i - 1], self.rotations[i]
        position = (1.0 - s) * p0 + s * p1
        rotation = R0.dot(pin.exp3(s * pin.log3(R0.T.dot(R1))))
        return position, np.asarray(rotation)
