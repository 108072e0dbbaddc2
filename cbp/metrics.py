# SPDX-License-Identifier: Apache-2.0
"""Metrics of a run, as the papers compare methods: one function for every executor.

:func:`run_metrics` reads a :class:`~cbp.trace.Trace` and reports each group of
metrics whose columns the trace has, so every method is measured the same way:

* always: ``samples``, ``events``, ``aborted`` (why the run ended early, or
  None), the computation time per sample or period, and with a robot the
  largest joint-limit violation;
* with a goal (the CAT paper's Sec. VI):

  - ``reached``: the end effector is within :data:`REACH_POSITION` and
    :data:`REACH_ROTATION` of the final goal at the end of the run;
  - ``total_time_s``: from the first goal change until it entered that region
    for the last time;
  - ``response_time_s``: from the first goal change until the end effector has
    moved :data:`MOVED` from where it started;

* with the simulator's ground truth: the sum of normal forces between robot and
  scene (peak, and time above :data:`CONTACT_FORCE`), the physical penetration,
  the clearance of the unpadded links to the declared objects;
* with command periods: steps per period (and in the periods that used their
  whole time budget), computation time, deadline misses;
* with step validation: rejected steps and the padded shapes' deepest
  penetration;
* with reported signals (the orbit paper): distance, view and roll errors,
  altitude and obstacle margins after the transient, base and arm travel.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from cbp.robot import FloatArray, RobotModel
from cbp.trace import FULL_PERIOD_NOTE, Trace

__all__ = [
    "CONTACT_FORCE",
    "MOVED",
    "REACH_POSITION",
    "REACH_ROTATION",
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


def run_metrics(trace: Trace, robot: RobotModel | None = None) -> dict[str, Any]:
    """The metrics of one run, by name (None where a metric is undefined).

    Args:
        trace: the run.
        robot: its robot, for the joint-limit violation (left out without).

    Raises:
        ValueError: the trace has no samples.
    """
    if trace.t.size == 0:
        raise ValueError("the trace is empty")
    metrics: dict[str, Any] = {}
    if trace.has_goal:
        metrics |= _tracking(trace)
    if trace.contact_force is not None:
        metrics |= _contact(trace)
    if trace.clearance is not None:
        clearance = trace.clearance[np.isfinite(trace.clearance)]
        least = float(np.min(clearance)) if clearance.size else None
        metrics["max_penetration_m"] = max(0.0, -least) if least is not None else 0.0
        metrics["min_clearance_m"] = least
    if trace.step_penetration is not None:
        depth = trace.step_penetration
        metrics["max_step_penetration_m"] = float(np.max(depth, initial=0.0))
        metrics["rejected_steps"] = trace.rejected_steps
    if trace.periods:
        metrics |= _periods(trace)
    if trace.signals:
        metrics |= _orbit(trace)
    if trace.u is not None and robot is not None:
        metrics |= _travel(trace.q, robot)
    if trace.compute_s is not None:
        compute_ms = trace.compute_s * 1e3
        metrics["compute_ms_median"] = float(np.median(compute_ms))
        metrics["compute_ms_p95"] = float(np.percentile(compute_ms, 95))
    if robot is not None:
        metrics["max_joint_limit_violation_rad"] = _limit_violation(trace.q, robot)
    metrics |= trace.counters
    metrics["samples"] = int(trace.t.size)
    metrics["events"] = len(trace.events)
    metrics["aborted"] = trace.aborted
    return metrics


def _tracking(trace: Trace) -> dict[str, Any]:
    """Reaching the final goal, response and total time, errors."""
    t = trace.t
    final_p = trace.goal_position[-1]
    final_R = trace.goal_rotation[-1]
    has_final = bool(np.all(np.isfinite(final_p)))
    start = trace.goal_change_time if trace.goal_change_time is not None else 0.0
    dp = np.linalg.norm(trace.ee_position - final_p, axis=1)
    relative = np.einsum("nji,jk->nik", trace.ee_rotation, final_R)
    cos = 0.5 * (np.trace(relative, axis1=1, axis2=2) - 1.0)
    dr = np.arccos(np.clip(cos, -1.0, 1.0))
    within = (dp <= REACH_POSITION) & (dr <= REACH_ROTATION)
    reached = has_final and bool(within[-1])
    total_time = None
    if reached:
        outside = np.flatnonzero(~within)
        k = outside[-1] + 1 if outside.size else 0
        total_time = max(float(t[k]) - start, 0.0)
    moved = np.linalg.norm(trace.ee_position - trace.ee_position[0], axis=1) >= MOVED
    response = np.flatnonzero(moved & (t >= start))
    error = trace.position_error
    return {
        "reached": reached,
        "response_time_s": (
            float(t[response[0]]) - start
            if response.size and trace.goal_change_time is not None
            else None
        ),
        "total_time_s": total_time,
        "final_position_error_m": float(dp[-1]) if has_final else None,
        "final_orientation_error_rad": float(dr[-1]) if has_final else None,
        "mean_position_error_m": float(np.nanmean(error)),
    }


def _contact(trace: Trace) -> dict[str, Any]:
    """The simulator's contact forces and physical penetration."""
    assert trace.contact_force is not None
    t = trace.t
    sample_dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    contact = trace.contact_force > CONTACT_FORCE
    penetration = trace.penetration
    return {
        "peak_contact_force_n": float(np.max(trace.contact_force)),
        "contact_duration_s": float(np.count_nonzero(contact)) * sample_dt,
        "physical_penetration_m": (
            float(np.max(penetration)) if penetration is not None else None
        ),
        "max_joint_tracking_error": _tracking_error(trace),
    }


def _tracking_error(trace: Trace) -> float | None:
    """The largest gap between a measured and a commanded coordinate [rad or m].

    The joint controller keeps it within a few hundredths of a radian, also
    in contact; far more means something forced the arm off its command (an
    obstacle that pressed it, a crush against another one). None without
    commands.
    """
    if trace.q_cmd is None or trace.q_cmd.shape != trace.q.shape:
        return None
    gap = np.abs(trace.q - trace.q_cmd)
    return float(np.nanmax(gap)) if gap.size else None


def _periods(trace: Trace) -> dict[str, Any]:
    """Steps and computation time per command period, deadline misses."""
    periods = trace.periods
    full = [p.steps for p in periods if p.note == FULL_PERIOD_NOTE]
    return {
        "steps_per_period_median": float(np.median([p.steps for p in periods])),
        "steps_per_full_period_median": float(np.median(full)) if full else None,
        "compute_ms_per_period_median": (
            float(np.median([p.compute_s for p in periods])) * 1e3
        ),
        "deadline_misses": sum(p.missed for p in periods),
        "periods": len(periods),
    }


def _orbit(trace: Trace) -> dict[str, Any]:
    """The orbit paper's quantities (from the signals the plugins report)."""
    s = trace.signals
    after = trace.t >= trace.transient_s

    def worst(values: FloatArray) -> float | None:
        v = np.abs(values)[after]
        return float(np.max(v)) if v.size else None

    def margin(key: str, bound: str) -> float | None:
        if key not in s or bound not in s:
            return None
        return float(np.min(s[key] - s[bound]))

    metrics: dict[str, Any] = {
        "transient_s": trace.transient_s,
        "distance_error_max_m": (
            worst(s["distance"] - s["distance_desired"])
            if "distance" in s and "distance_desired" in s
            else None
        ),
        "view_error_max_deg": worst(s["view_error_deg"])
        if "view_error_deg" in s
        else None,
        "roll_max_deg": worst(s["roll_deg"]) if "roll_deg" in s else None,
        "altitude_margin_min_m": margin("altitude", "min_altitude"),
        "obstacle_margin_min_m": margin("obstacle_distance", "min_obstacle_distance"),
    }
    return metrics


def _travel(q: FloatArray, robot: RobotModel) -> dict[str, float]:
    """How far the measured base [m] and joints [rad] moved, sample to sample.

    Reported for velocity-controlled runs: the base's share is the length of its
    translation (a planar or floating base), the joints' the sum of their
    absolute motions.
    """
    held = np.array([robot.difference(a, b) for a, b in itertools.pairwise(q)])
    held = held.reshape(len(q) - 1, robot.nv)
    arm = robot.articulated_v_indices()
    metrics = {"arm_travel_rad": float(np.sum(np.abs(held[:, arm])))}
    if robot.base != "fixed":
        linear = 2 if robot.base == "planar" else 3
        metrics["base_travel_m"] = float(
            np.sum(np.linalg.norm(held[:, :linear], axis=1))
        )
    return metrics


def _limit_violation(q: FloatArray, robot: RobotModel) -> float:
    """Largest distance of a bounded joint beyond its limits [rad or m]."""
    bq = robot.bounded_q
    if not len(bq):
        return 0.0
    lower, upper = robot.lower_limits[bq], robot.upper_limits[bq]
    beyond = np.maximum(lower - q[:, bq], q[:, bq] - upper)
    return max(float(np.max(beyond, initial=0.0)), 0.0)
