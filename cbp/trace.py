# SPDX-License-Identifier: Apache-2.0
"""What a simulated run recorded: samples, command periods and events.

Every executor that runs in the simulator (CAT, and the IK, MP and JT methods)
returns a :class:`RunTrace`; metrics, plots and comparisons read only this.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cbp.robot import FloatArray

__all__ = ["FULL_PERIOD_NOTE", "PeriodRecord", "RunTrace"]

#: The note of a period whose planner used its whole time budget.
FULL_PERIOD_NOTE = "time budget spent"


@dataclass(frozen=True)
class PeriodRecord:
    """One command period of a trajectory executor.

    Attributes:
        t: start of the period (simulated time) [s].
        period: its length [s] (adaptive).
        steps: planning steps taken (QP steps for CAT).
        compute_s: wall time of the computation [s].
        missed: the result came after the deadline and was discarded.
        spliced: a new trajectory was spliced in.
        note: why nothing was spliced, or what ended the computation.
    """

    t: float
    period: float
    steps: int
    compute_s: float
    missed: bool
    spliced: bool
    note: str = ""


@dataclass
class RunTrace:
    """Samples of a simulated run (at the simulator's recording rate).

    Attributes:
        method: executor name.
        t: sample times (M,) [s].
        q: measured joint positions (M, nq).
        q_cmd: commanded joint positions (M, nq) (the measured ones under torque
            control).
        ee_position: end-effector positions (M, 3) [m].
        ee_rotation: end-effector rotations (M, 3, 3).
        goal_position: the operator's goal in effect (M, 3) [m] (the last valid
            sample; NaN before the first).
        goal_rotation: (M, 3, 3).
        contact_force: largest sum of contact normal forces between robot and
            scene since the previous sample (M,) [N].
        wrist_force: the hand's share of it (M,) [N].
        penetration: deepest physical penetration since the previous sample (M,) [m].
        clearance: ground-truth distance from the unpadded links to the declared
            objects (M,) [m]; NaN where not computed, +inf with no objects.
        goal_change_time: time of the first change of the goal [s], or None.
        periods: command periods (trajectory executors).
        events: (time, message) of every rejected goal, failed solve, discarded
            result.
    """

    method: str
    t: FloatArray
    q: FloatArray
    q_cmd: FloatArray
    ee_position: FloatArray
    ee_rotation: FloatArray
    goal_position: FloatArray
    goal_rotation: FloatArray
    contact_force: FloatArray
    wrist_force: FloatArray
    penetration: FloatArray
    clearance: FloatArray
    goal_change_time: float | None
    periods: list[PeriodRecord] = field(default_factory=list)
    events: list[tuple[float, str]] = field(default_factory=list)

    @property
    def position_error(self) -> FloatArray:
        """End effector to goal distance (M,) [m]."""
        return np.asarray(np.linalg.norm(self.ee_position - self.goal_position, axis=1))

    @property
    def rotation_error(self) -> FloatArray:
        """Rotation angle between end effector and goal (M,) [rad]."""
        relative = np.einsum("nji,njk->nik", self.ee_rotation, self.goal_rotation)
        cos = 0.5 * (np.trace(relative, axis1=1, axis2=2) - 1.0)
        return np.asarray(np.arccos(np.clip(cos, -1.0, 1.0)))
