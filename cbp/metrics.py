# SPDX-License-Identifier: Apache-2.0
"""Metrics of a simulated run, as the CAT paper's Sec. VI compares methods.

All are computed from a :class:`~cbp.trace.RunTrace`, so every method is
measured the same way:

* ``reached``: the end effector is within :data:`REACH_POSITION` and
  :data:`REACH_ROTATION` of the final goal at the end of the run, and has stayed
  there since ``total_time_s`` after the first goal change;
* ``response_time_s``: from the first goal change until the end effector has
  moved :data:`MOVED` from where it started;
* ``steps_per_full_period_median``: planning steps in the periods that used
  their whole time budget (the others stopped early: converged, blocked);
* contact: the sum of normal forces between robot and scene, its peak and the
  time it is above :data:`CONTACT_FORCE`; penetration and clearance are the
  ground truth (the unpadded link hulls against the declared objects).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cbp.robot import FloatArray, RobotModel
from cbp.trace import FULL_PERIOD_NOTE, KinematicTrace, RunTrace, VelocityTrace

__all__ = [
    "CONTACT_FORCE",
    "MOVED",
    "REACH_POSITION",
    "REACH_ROTATION",
    "kinematic_metrics",
    "orbit_metrics",
    "run_metrics",
]

REACH_POSITION = 0.01
"""A goal counts as reached within this distance [m] ..."""
REACH_ROTATION = float(np.deg2rad(5.0))
"""... and this rotation [rad]."""
MOVED = 0.005
"""The end effector has responded once it moved this far [m]."""
CONTACT_FORCE = 0.05
"""Contact counts toward the duration above this force [N]."""


def run_metrics(trace: RunTrace) -> dict[str, Any]:
    """The metrics of one run (keys as in the CAT issue; None where undefined)."""
    t = trace.t
    if t.size == 0:
        raise ValueError("the trace is empty")
    final_p = trace.goal_position[-1]
    final_R = trace.goal_rotation[-1]
    has_goal = bool(np.all(np.isfinite(final_p)))
    start = trace.goal_change_time if trace.goal_change_time is not None else 0.0
    dp = np.linalg.norm(trace.ee_position - final_p, axis=1)
    relative = np.einsum("nji,jk->nik", trace.ee_rotation, final_R)
    cos = 0.5 * (np.trace(relative, axis1=1, axis2=2) - 1.0)
    dr = np.arccos(np.clip(cos, -1.0, 1.0))
    within = (dp <= REACH_POSITION) & (dr <= REACH_ROTATION) if has_goal else None
    reached = bool(within is not None and within[-1])
    total_time = None
    if reached and within is not None:
        outside = np.flatnonzero(~within)
        k = outside[-1] + 1 if outside.size else 0
        total_time = max(float(t[k]) - start, 0.0)
    moved = np.linalg.norm(trace.ee_position - trace.ee_position[0], axis=1) >= MOVED
    response = np.flatnonzero(moved & (t >= start))
    sample_dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    contact = trace.contact_force > CONTACT_FORCE
    periods = trace.periods
    clearance = trace.clearance[np.isfinite(trace.clearance)]
    min_clearance = float(np.min(clearance)) if clearance.size else None
    error = trace.position_error
    return {
        "reached": reached,
        "response_time_s": (
            float(t[response[0]]) - start
            if response.size and trace.goal_change_time is not None
            else None
        ),
        "total_time_s": total_time,
        "final_position_error_m": float(dp[-1]) if has_goal else None,
        "final_orientation_error_rad": float(dr[-1]) if has_goal else None,
        "mean_position_error_m": (
            float(np.nanmean(error)) if np.any(np.isfinite(error)) else None
        ),
        "peak_contact_force_n": float(np.max(trace.contact_force)),
        "contact_duration_s": float(np.count_nonzero(contact)) * sample_dt,
        "max_penetration_m": (
            max(0.0, -min_clearance) if min_clearance is not None else 0.0
        ),
        "physical_penetration_m": float(np.max(trace.penetration)),
        "min_clearance_m": min_clearance,
        "steps_per_period_median": (
            float(np.median([p.steps for p in periods])) if periods else None
        ),
        "steps_per_full_period_median": (
            float(np.median(full)) if (full := _full_periods(trace)) else None
        ),
        "compute_ms_per_period_median": (
            float(np.median([p.compute_s for p in periods])) * 1e3 if periods else None
        ),
        "deadline_misses": sum(p.missed for p in periods),
        "periods": len(periods),
        "events": len(trace.events),
    }


def _full_periods(trace: RunTrace) -> list[int]:
    """Steps of the periods whose computation used the whole time budget."""
    return [p.steps for p in trace.periods if p.note == FULL_PERIOD_NOTE]


#: A goal counts as reached within these tolerances.
REACHED_POSITION = 0.01  # [m]
REACHED_ROTATION = np.deg2rad(2.0)  # [rad]


def kinematic_metrics(
    trace: KinematicTrace, robot: RobotModel, last_key: float
) -> dict[str, Any]:
    """Summarize a kinematic run: tracking errors, timing, limit margins, events.

    Args:
        trace: the run.
        robot: its robot (for the joint limits).
        last_key: when the goal stops moving [s]; reaching is counted after it.
    """
    q = trace.q
    bq = robot.bounded_q
    lower, upper = robot.lower_limits[bq], robot.upper_limits[bq]
    violation = float(
        np.max(np.maximum(lower - q[:, bq], q[:, bq] - upper), initial=0.0)
    )
    within = (trace.position_error <= REACHED_POSITION) & (
        trace.rotation_error <= REACHED_ROTATION
    )
    after = trace.t >= last_key
    reached_at = trace.t[after & within]
    step_us = trace.solve_time * 1e6
    return {
        "final_position_error_m": _finite(trace.position_error[-1]),
        "final_rotation_error_deg": _finite(np.rad2deg(trace.rotation_error[-1])),
        "mean_position_error_m": _finite(float(np.nanmean(trace.position_error))),
        "goal_reached": bool(reached_at.size > 0),
        "time_to_reach_after_last_keyframe_s": (
            float(reached_at[0] - last_key) if reached_at.size else None
        ),
        "max_joint_limit_violation_rad": max(violation, 0.0),
        "step_time_us_median": float(np.median(step_us)),
        "step_time_us_p95": float(np.percentile(step_us, 95)),
        "steps": int(trace.t.size),
        "events": len(trace.events),
    }


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def orbit_metrics(trace: VelocityTrace, transient: float) -> dict[str, float | None]:
    """Metrics of an orbit run; the first ``transient`` [s] is left out."""
    s = trace.signals
    after = trace.t >= transient

    def worst(key: str, values: FloatArray | None = None) -> float | None:
        if key not in s and values is None:
            return None
        v = np.abs(values if values is not None else s[key])[after]
        return float(np.max(v)) if v.size else None

    def margin(key: str, bound: str) -> float | None:
        if key not in s:
            return None
        return float(np.min(s[key] - s[bound]))

    base_xy = trace.q[:, :2]
    return {
        "transient_s": transient,
        "distance_error_max_m": (
            worst("distance", s["distance"] - s["distance_desired"])
            if "distance" in s
            else None
        ),
        "view_error_max_deg": worst("view_error_deg"),
        "roll_max_deg": worst("roll_deg"),
        "altitude_margin_min_m": margin("altitude", "min_altitude"),
        "obstacle_margin_min_m": margin("obstacle_distance", "min_obstacle_distance"),
        "base_travel_m": float(
            np.sum(np.linalg.norm(np.diff(base_xy, axis=0), axis=1))
        ),
        "arm_travel_rad": float(np.sum(np.abs(np.diff(trace.q[:, 4:], axis=0)))),
        "compute_ms_per_tick_median": float(np.median(trace.compute_s) * 1e3),
        "events": float(len(trace.events)),
    }
