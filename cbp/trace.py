# SPDX-License-Identifier: Apache-2.0
"""What runs record: samples, command periods and events.

Every executor that runs in the simulator (CAT, and the IK, MP and JT methods)
returns a :class:`RunTrace`; metrics, plots and comparisons read only this. The
kinematic executor returns a :class:`KinematicTrace` (one row per QP step, no
simulator) and the velocity executor a :class:`VelocityTrace` (one row per
tick, with the signals its plugins report).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cbp.robot import FloatArray

__all__ = [
    "FULL_PERIOD_NOTE",
    "KinematicTrace",
    "PeriodRecord",
    "RunTrace",
    "VelocityTrace",
]

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


@dataclass
class KinematicTrace:
    """What a kinematic run recorded, one row per control step.

    Attributes:
        t: times [s] (N,).
        q: configurations (N, nq).
        ee_position: end-effector position (N, 3) [m].
        goal_position: goal position (N, 3) [m], NaN without a goal.
        position_error: end-effector to goal distance (N,) [m].
        rotation_error: rotation angle between end effector and goal (N,) [rad].
        solve_time: engine step wall time (N,) [s].
        events: (time, message) for every goal rejected or step not solved.
        joint_names: names of the model's joints.
        penetration: deepest penetration of the padded links at each step (N,)
            [m]; empty without a collision world.
        rejected_steps: steps rejected by step validation.
    """

    t: FloatArray
    q: FloatArray
    ee_position: FloatArray
    goal_position: FloatArray
    position_error: FloatArray
    rotation_error: FloatArray
    solve_time: FloatArray
    events: list[tuple[float, str]] = field(default_factory=list)
    joint_names: list[str] = field(default_factory=list)
    penetration: FloatArray = field(default_factory=lambda: np.zeros(0))
    rejected_steps: int = 0


@dataclass
class VelocityTrace:
    """What a velocity-executor run recorded, one row per tick.

    Attributes:
        t: tick times (N,) [s].
        q: measured configurations (N, nq).
        u: commanded velocities (N, nv).
        compute_s: wall time of each tick's QP (N,) [s].
        inputs: the inputs' values at each tick, by entry name (N, k).
        signals: the orbit's quantities over time (see :func:`orbit_signals`).
        events: (time, message) of refused inputs and failed solves.
    """

    t: FloatArray
    q: FloatArray
    u: FloatArray
    compute_s: FloatArray
    inputs: dict[str, FloatArray]
    signals: dict[str, FloatArray] = field(default_factory=dict)
    events: list[tuple[float, str]] = field(default_factory=list)
