# SPDX-License-Identifier: Apache-2.0
"""Goal streams: the operator's goal pose as a function of time.

A stream is sampled at the command rate (30 Hz by default), like an operator's
input device. Kinds:

* ``keyframes``: poses at times; translation interpolated linearly, rotation by
  slerp;
* ``step``: each keyframe's pose held from its time on (a jump);
* ``function``: position and roll-pitch-yaw as expressions of ``t``
  (:mod:`cbp.expressions`), e.g. sinusoids;
* ``recorded``: a CSV of timestamped poses (``t,x,y,z,qx,qy,qz,qw``), so that an
  operator's session is recorded once and replayed to every method, as the CAT
  paper did. :func:`write_recorded` writes one from any stream.

A sample may be malformed (a NaN in a recording): the stream returns it as it
is, and the executor rejects it and keeps the previous goal.
"""

from __future__ import annotations

import bisect
import csv
import io
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Protocol, runtime_checkable

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.expressions import TimeFunction, compile_time_function
from cbp.files import MAX_TABLE_BYTES, read_text
from cbp.robot import FloatArray
from cbp.spatial import Pose

__all__ = [
    "RECORDED_COLUMNS",
    "FunctionGoal",
    "GoalSource",
    "GoalSpec",
    "GoalStream",
    "Keyframe",
    "LiveGoalSource",
    "write_recorded",
]

#: Times closer than this to a keyframe or sample are on it [s] (recordings are
#: written with microsecond precision).
TIME_TOLERANCE = 1e-6

#: Header of a recorded goal file: time [s], position [m], quaternion (x, y, z, w).
RECORDED_COLUMNS = ("t", "x", "y", "z", "qx", "qy", "qz", "qw")


@dataclass(frozen=True, kw_only=True)
class Keyframe:
    """A goal pose at a time."""

    t: float
    """Time [s] from the start of the run."""
    pose: Pose
    """The goal pose, world frame."""


@dataclass(frozen=True, kw_only=True)
class FunctionGoal:
    """A goal pose whose coordinates are expressions of the time ``t`` [s]."""

    position: tuple[str | float, str | float, str | float]
    """x, y, z [m]: numbers or expressions of t."""
    rpy_deg: tuple[str | float, str | float, str | float] = (0.0, 0.0, 0.0)
    """Roll, pitch, yaw [deg] (as in :class:`~cbp.spatial.Pose`): numbers or
    expressions of t."""

    def __post_init__(self) -> None:
        """Every expression compiles."""
        for name in ("position", "rpy_deg"):
            for i, text in enumerate(getattr(self, name)):
                compile_time_function(text, f"{name}[{i}]")


@dataclass(frozen=True, kw_only=True)
class GoalSpec:
    """The ``goal:`` section of a scenario."""

    type: Literal["keyframes", "step", "function", "recorded"]
    """``keyframes``: interpolate between poses; ``step``: jump at each time;
    ``function``: expressions of t; ``recorded``: a CSV file of poses."""
    task: str | None = None
    """Name of the task entry that receives the goal (default: the first
    ``goal_pose`` task)."""
    rate_hz: float = 30.0
    """Rate at which the goal is sampled and sent [Hz]."""
    keyframes: list[Keyframe] = field(default_factory=list)
    """``keyframes`` and ``step``: poses at times, in increasing time order."""
    function: FunctionGoal | None = None
    """``function``: the pose's expressions."""
    file: str = ""
    """``recorded``: CSV file (columns t,x,y,z,qx,qy,qz,qw), relative to the
    scenario file; samples are interpolated like keyframes."""

    def __post_init__(self) -> None:
        """The fields the type needs are there, and only those."""
        if not 0 < self.rate_hz <= 1000.0:
            raise ConfigError(f"must be in (0, 1000] Hz, got {self.rate_hz}", "rate_hz")
        needs = {
            "keyframes": "keyframes",
            "step": "keyframes",
            "function": "function",
            "recorded": "file",
        }[self.type]
        given = {
            "keyframes": bool(self.keyframes),
            "function": self.function is not None,
            "file": bool(self.file),
        }
        if not given[needs]:
            raise ConfigError(f"a '{self.type}' goal needs '{needs}:'", needs)
        for other, present in given.items():
            if present and other != needs:
                raise ConfigError(
                    f"'{other}:' does not apply to a '{self.type}' goal "
                    f"(it uses '{needs}:')",
                    other,
                )
        times = [k.t for k in self.keyframes]
        for i in range(1, len(times)):
            if times[i] <= times[i - 1]:
                raise ConfigError(
                    f"times must increase; {times[i]} follows {times[i - 1]}",
                    f"keyframes[{i}].t",
                )


class GoalSource(Protocol):
    """What a simulated run samples the operator's goal from.

    A scenario's :class:`GoalStream`, or a live source such as the teleoperation
    page's (:class:`cbp.teleop.LiveGoal`).
    """

    @property
    def rate_hz(self) -> float:
        """Rate at which the goal is sampled and sent [Hz]."""
        ...

    def sample(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Goal position (3,) and rotation (3, 3) at time ``t`` [s]."""
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


class GoalStream:
    """Samples a :class:`GoalSpec`: ``pose(t)`` returns the goal at time t.

    Args:
        spec: the goal section.
        folder: where a recorded file is resolved from.

    Raises:
        ConfigError: a recorded file that cannot be read (location ``file``).
    """

    def __init__(self, spec: GoalSpec, folder: Path | None = None) -> None:
        """Convert keyframes, compile expressions or read the recording once."""
        self.spec = spec
        self.period = 1.0 / spec.rate_hz
        self._functions: list[TimeFunction] = []
        self._times: list[float] = []
        self._positions: list[FloatArray] = []
        self._rotations: list[FloatArray] = []
        if spec.type == "function":
            assert spec.function is not None
            f = spec.function
            self._functions = [
                compile_time_function(x, f"function.position[{i}]")
                for i, x in enumerate(f.position)
            ] + [
                compile_time_function(x, f"function.rpy_deg[{i}]")
                for i, x in enumerate(f.rpy_deg)
            ]
        elif spec.type == "recorded":
            path = (folder or Path.cwd()) / spec.file
            self._times, self._positions, self._rotations = _read_recorded(path)
        else:
            for k in spec.keyframes:
                M = k.pose.to_se3()
                self._times.append(k.t)
                self._positions.append(np.array(M.translation))
                self._rotations.append(np.array(M.rotation))

    @property
    def rate_hz(self) -> float:
        """Rate at which the goal is sampled and sent [Hz]."""
        return self.spec.rate_hz

    @property
    def end_time(self) -> float:
        """Time of the last keyframe or sample (0 for a function) [s]."""
        return self._times[-1] if self._times else 0.0

    def sample(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Goal position (3,) and rotation (3, 3) at time ``t`` [s].

        Held before the first and after the last keyframe or sample. May contain
        NaN if the recording does.
        """
        if self._functions:
            values = [f(t) for f in self._functions]
            rotation = pin.rpy.rpyToMatrix(*np.deg2rad(values[3:]))
            return np.array(values[:3]), np.asarray(rotation)
        i = bisect.bisect_right(self._times, t)
        if i == 0:
            return self._positions[0], self._rotations[0]
        if i == len(self._times) or self.spec.type == "step":
            return self._positions[i - 1], self._rotations[i - 1]
        t0, t1 = self._times[i - 1], self._times[i]
        if t - t0 < TIME_TOLERANCE:  # on a sample (within the file's precision)
            return self._positions[i - 1], self._rotations[i - 1]
        if t1 - t < TIME_TOLERANCE:
            return self._positions[i], self._rotations[i]
        s = (t - t0) / (t1 - t0)
        p0, p1 = self._positions[i - 1], self._positions[i]
        R0, R1 = self._rotations[i - 1], self._rotations[i]
        position = (1.0 - s) * p0 + s * p1
        if not (np.all(np.isfinite(R0)) and np.all(np.isfinite(R1))):
            return position, np.full((3, 3), np.nan)
        rotation = R0.dot(pin.exp3(s * pin.log3(R0.T.dot(R1))))
        return position, rotation

    def pose(self, t: float) -> pin.SE3:
        """The goal at time ``t`` as an SE3 (NaN entries pass through)."""
        position, rotation = self.sample(t)
        return pin.SE3(rotation, position)


def _read_recorded(
    path: Path,
) -> tuple[list[float], list[FloatArray], list[FloatArray]]:
    try:
        text = read_text(path, "recorded goal", MAX_TABLE_BYTES)
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except ConfigError as exc:
        raise ConfigError(exc.message, "file") from None
    except csv.Error as exc:
        raise ConfigError(f"{path}: not a CSV table: {exc}", "file") from None
    if not rows or tuple(c.strip() for c in rows[0]) != RECORDED_COLUMNS:
        raise ConfigError(
            f"{path}: the first line must be {','.join(RECORDED_COLUMNS)}", "file"
        )
    times: list[float] = []
    positions: list[FloatArray] = []
    rotations: list[FloatArray] = []
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(RECORDED_COLUMNS):
            raise ConfigError(
                f"{path}:{line}: expected {len(RECORDED_COLUMNS)} values, "
                f"got {len(row)}",
                "file",
            )
        values = np.array([_number(v) for v in row])
        t = values[0]
        if not np.isfinite(t) or (times and t <= times[-1]):
            raise ConfigError(
                f"{path}:{line}: times must be finite and increase, got {row[0]!r}",
                "file",
            )
        times.append(float(t))
        positions.append(values[1:4])
        quat = values[4:8]
        norm = np.linalg.norm(quat)
        if np.isfinite(norm) and norm > 1e-9:
            x, y, z, w = quat / norm
            rotations.append(np.asarray(pin.Quaternion(w, x, y, z).matrix()))
        else:
            rotations.append(np.full((3, 3), np.nan))
    if not times:
        raise ConfigError(f"{path}: no samples", "file")
    return times, positions, rotations


def _number(text: str) -> float:
    """A CSV cell as a float; malformed cells become NaN (rejected at run time)."""
    try:
        return float(text)
    except ValueError:
        return float("nan")


def recorded_goal_overrides(path: Path, settle: float = 2.0) -> dict[str, str]:
    """Scenario overrides that replace the goal with the recording at ``path``.

    The run lasts until the recording's last sample and ``settle`` seconds more
    (``cbp compare --goal``: a teleoperation session replayed to every method).

    Raises:
        ConfigError: the file cannot be read as a recorded goal.
    """
    path = Path(path).resolve()
    times, _, _ = _read_recorded(path)
    goal = {"type": "recorded", "file": str(path)}
    return {"goal": json.dumps(goal), "duration": f"{times[-1] + settle:.6f}"}


def write_recorded(
    path: Path, times: Sequence[float], positions: FloatArray, rotations: FloatArray
) -> None:
    """Write poses (positions (N, 3), rotations (N, 3, 3)) as a recorded goal file."""
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(RECORDED_COLUMNS)
        for t, p, R in zip(times, positions, rotations, strict=True):
            q = pin.Quaternion(np.asarray(R))
            writer.writerow(
                [f"{t:.6f}", *(f"{v:.6f}" for v in p)]
                + [f"{v:.8f}" for v in (q.x, q.y, q.z, q.w)]
            )
