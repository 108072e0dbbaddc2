# SPDX-License-Identifier: Apache-2.0
"""What a run records: one :class:`Trace` type for every executor.

A trace is a table of samples (``t``, ``q`` and the end effector's and goal's
poses, for every executor) with the columns an executor can fill and the others
leave as ``None``:

* the simulator's ground truth (``q_cmd``, contact forces, physical penetration,
  clearance to the declared objects): the simulated executors (CAT, IK, MP, JT);
* the wall time of each sample's computation (``compute_s``): the executors that
  compute once per sample (kinematic, velocity); the trajectory executors
  record it per command period (``periods``) instead;
* commanded velocities, operator inputs and the signals plugins report: the
  velocity executor.

:func:`cbp.metrics.run_metrics`, :mod:`cbp.plots` and :mod:`cbp.report` read a
column when it is there, so a new executor gets metrics, plots and a report by
filling the columns it has.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cbp.robot import FloatArray

__all__ = ["FORCED_OFF", "FULL_PERIOD_NOTE", "PeriodRecord", "Trace"]

#: The note of a period whose planner used its whole time budget.
FULL_PERIOD_NOTE = "time budget spent"


#: A joint this far from its command [rad or m] was forced there by what the
#: arm touches: the joint controller tracks within about 0.02 rad, also in
#: contact (the generated moving scenes' declared runs).
FORCED_OFF = 0.1


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
class Trace:
    """The samples of one run (M samples, at the executor's recording rate).

    Attributes:
        method: executor name.
        t: sample times (M,) [s].
        q: measured joint positions (M, nq).
        ee_position: end-effector positions (M, 3) [m].
        ee_rotation: end-effector rotations (M, 3, 3).
        goal_position: the goal in effect (M, 3) [m]: the last accepted one, NaN
            before the first and in runs without a goal.
        goal_rotation: (M, 3, 3), NaN likewise.
        goal_change_time: time of the first change of the goal [s], or None.
        q_names: a name per configuration coordinate
            (:meth:`~cbp.robot.RobotModel.coordinate_names`).
        v_names: a name per velocity coordinate.
        events: (time, message) of every rejected goal or input, failed solve,
            rejected step, discarded result.
        compute_s: wall time of the computation at each sample (M,) [s].
        q_cmd: commanded joint positions (M, nq) (the measured ones under torque
            control).
        contact_force: largest sum of contact normal forces between robot and
            scene since the previous sample (M,) [N].
        wrist_force: the hand's share of it (M,) [N].
        penetration: deepest physical penetration since the previous sample
            (M,) [m].
        clearance: ground-truth distance from the unpadded links to the declared
            objects (M,) [m]; NaN where not computed, +inf with no objects.
        step_penetration: deepest penetration of the padded shapes where each
            validated step ended (M,) [m] (the collision model's view).
        rejected_steps: steps refused by step validation.
        periods: command periods (trajectory executors).
        u: commanded velocities (M, nv).
        inputs: the operator inputs' values at each sample, by entry name (M, k).
        signals: what the plugins report at each sample, by key (M,)
            (:class:`~cbp.plugin.ReportsSignals`).
        transient_s: metrics of the steady behaviour leave out the samples
            before this time [s].
        aborted: why the run ended before its duration
            (:mod:`cbp.run.faults`), or None.
        counters: numbers an executor counts over the run, by metric name
            (the hybrid's ``plans``); they go into the metrics as they are.
        incomplete: the stages after the control loop that failed (``clearance``;
            :func:`cbp.report.write_outputs` adds its own), each also an event;
            the outputs are written without them.
    """

    method: str
    t: FloatArray
    q: FloatArray
    ee_position: FloatArray
    ee_rotation: FloatArray
    goal_position: FloatArray
    goal_rotation: FloatArray
    goal_change_time: float | None = None
    q_names: list[str] = field(default_factory=list)
    v_names: list[str] = field(default_factory=list)
    events: list[tuple[float, str]] = field(default_factory=list)
    compute_s: FloatArray | None = None
    q_cmd: FloatArray | None = None
    contact_force: FloatArray | None = None
    wrist_force: FloatArray | None = None
    penetration: FloatArray | None = None
    clearance: FloatArray | None = None
    step_penetration: FloatArray | None = None
    rejected_steps: int = 0
    periods: list[PeriodRecord] = field(default_factory=list)
    u: FloatArray | None = None
    inputs: dict[str, FloatArray] = field(default_factory=dict)
    signals: dict[str, FloatArray] = field(default_factory=dict)
    transient_s: float = 0.0
    aborted: str | None = None
    counters: dict[str, float] = field(default_factory=dict)
    incomplete: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        """Every column has one row per sample."""
        m = self.t.shape[0]
        for name in (
            "q",
            "ee_position",
            "ee_rotation",
            "goal_position",
            "goal_rotation",
            "compute_s",
            "q_cmd",
            "contact_force",
            "wrist_force",
            "penetration",
            "clearance",
            "step_penetration",
            "u",
        ):
            column = getattr(self, name)
            if column is not None and column.shape[0] != m:
                raise ValueError(
                    f"trace column {name} has {column.shape[0]} rows, t has {m}"
                )
        for group in (self.inputs, self.signals):
            for key, column in group.items():
                if column.shape[0] != m:
                    raise ValueError(
                        f"trace column {key} has {column.shape[0]} rows, t has {m}"
                    )

    @property
    def has_goal(self) -> bool:
        """Whether a goal was in effect at any sample."""
        return bool(np.any(np.isfinite(self.goal_position[:, 0])))

    @property
    def position_error(self) -> FloatArray:
        """End effector to goal distance (M,) [m]; NaN without a goal."""
        return np.asarray(np.linalg.norm(self.ee_position - self.goal_position, axis=1))

    @property
    def rotation_error(self) -> FloatArray:
        """Rotation angle between end effector and goal (M,) [rad]; NaN without."""
        relative = np.einsum("nji,njk->nik", self.ee_rotation, self.goal_rotation)
        cos = 0.5 * (np.trace(relative, axis1=1, axis2=2) - 1.0)
        return np.asarray(np.arccos(np.clip(cos, -1.0, 1.0)))
