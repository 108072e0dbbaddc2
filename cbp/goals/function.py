# SPDX-License-Identifier: Apache-2.0
"""``type: function``: the goal pose's coordinates as expressions of time."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.expressions import check_over, compile_time_function, run_times
from cbp.goals.base import GoalSpec, GoalStream
from cbp.robot import FloatArray

__all__ = ["FunctionGoal", "FunctionGoalSpec", "PoseExpressions"]


@dataclass(frozen=True, kw_only=True)
class PoseExpressions:
    """A goal pose whose coordinates are expressions of the time ``t`` [s]."""

    position: tuple[str | float, str | float, str | float]
    """x, y, z [m]: numbers or expressions of t (:mod:`cbp.expressions`)."""
    rpy_deg: tuple[str | float, str | float, str | float] = (0.0, 0.0, 0.0)
    """Roll, pitch, yaw [deg] (as in :class:`~cbp.spatial.Pose`): numbers or
    expressions of t."""

    def __post_init__(self) -> None:
        """Every expression compiles."""
        for name, text in self.expressions():
            compile_time_function(text, name)

    def expressions(self) -> list[tuple[str, str | float]]:
        """Each coordinate's place (``position[1]``) and expression, in order."""
        return [
            (f"{name}[{i}]", text)
            for name in ("position", "rpy_deg")
            for i, text in enumerate(getattr(self, name))
        ]


@dataclass(frozen=True, kw_only=True)
class FunctionGoalSpec(GoalSpec):
    """``type: function``: position and roll-pitch-yaw as expressions of ``t``.

    Sinusoids, ramps, anything :mod:`cbp.expressions` accepts; each expression
    is evaluated at every time the run samples it before the run starts.
    """

    type: str = "function"
    function: PoseExpressions
    """The pose's expressions."""


class FunctionGoal(GoalStream):
    """Samples a ``function`` section: its expressions evaluated at each time.

    Args:
        spec: the section.
        folder: unused (no file).
    """

    type_name = "function"
    Spec = FunctionGoalSpec

    def __init__(self, spec: FunctionGoalSpec, folder: Path | None = None) -> None:
        """Compile the six expressions once."""
        super().__init__(spec, folder)
        self.functions = [
            (f"function.{where}", compile_time_function(text, f"function.{where}"))
            for where, text in spec.function.expressions()
        ]

    def sample(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Goal position (3,) [m] and rotation (3, 3) at time ``t`` [s], world frame."""
        values = [f(t) for _, f in self.functions]
        rotation = pin.rpy.rpyToMatrix(*np.deg2rad(values[3:]))
        return np.array(values[:3]), np.asarray(rotation)

    def problems(self, duration: float) -> list[ConfigError]:
        """Each expression that fails or is not finite at a time the run samples it."""
        times = run_times(duration, self.rate_hz)
        found = []
        for where, function in self.functions:
            try:
                check_over(function, times, where)
            except ConfigError as exc:
                found.append(exc)
        return found
