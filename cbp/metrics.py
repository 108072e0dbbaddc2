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

from cbp.trace import FULL_PERIOD_NOTE, RunTrace

__all__ = [
    "CONTACT_FORCE",
    "MOVED",
    "REACH_POSITION",
    "REACH_ROTATION",
    "compute_metrics",
]

REACH_POSITION = 0.01
"""A goal counts as reached within this distance [m] ..."""
REACH_ROTATION = float(np.deg2rad(5.0))
"""... and this rotation [rad]."""
MOVED = 0.005
"""The end effector has responded once it moved this far [m]."""
CONTACT_FORCE = 0.05
"""Contact counts toward the duration above this force [N]."""


def compute_metrics(trace: RunTrace) -> dict[str, Any]:
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
