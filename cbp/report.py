# SPDX-License-Identifier: Apache-2.0
"""Outputs of a run: trace.csv, metrics.json, plots and report.md."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np

from cbp.executors.kinematic import Trace
from cbp.scenario import Scenario

#: A goal counts as reached within these tolerances.
REACHED_POSITION = 0.01  # [m]
REACHED_ROTATION = np.deg2rad(2.0)  # [rad]


def compute_metrics(scenario: Scenario, trace: Trace) -> dict[str, Any]:
    """Summarize a run: tracking errors, timing, limit margins, events."""
    robot = scenario.robot
    q = trace.q
    bq = robot.bounded_q
    lower, upper = robot.lower_limits[bq], robot.upper_limits[bq]
    violation = float(
        np.max(np.maximum(lower - q[:, bq], q[:, bq] - upper), initial=0.0)
    )
    within = (trace.position_error <= REACHED_POSITION) & (
        trace.rotation_error <= REACHED_ROTATION
    )
    last_key = scenario.spec.goal.keyframes[-1].t if scenario.spec.goal else 0.0
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


def write_outputs(scenario: Scenario, trace: Trace, out: Path) -> dict[str, Any]:
    """Write trace.csv, metrics.json, tracking.png and report.md into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    metrics = compute_metrics(scenario, trace)
    with open(out / "trace.csv", "w", newline="") as f:
        writer = csv.writer(f)
        q_names = [f"q{i}" for i in range(trace.q.shape[1])]
        writer.writerow(
            [
                "t",
                *q_names,
                "ee_x",
                "ee_y",
                "ee_z",
                "goal_x",
                "goal_y",
                "goal_z",
                "position_error",
                "rotation_error",
                "step_time",
            ]
        )
        for i in range(trace.t.size):
            writer.writerow(
                [
                    f"{trace.t[i]:.4f}",
                    *(f"{v:.6f}" for v in trace.q[i]),
                    *(f"{v:.6f}" for v in trace.ee_position[i]),
                    *(f"{v:.6f}" for v in trace.goal_position[i]),
                    f"{trace.position_error[i]:.6f}",
                    f"{trace.rotation_error[i]:.6f}",
                    f"{trace.solve_time[i]:.6e}",
                ]
            )
    result = {
        "scenario": scenario.spec.name,
        "method": scenario.spec.method.name,
        "metrics": metrics,
        "events": [{"t": t, "message": m} for t, m in trace.events],
    }
    (out / "metrics.json").write_text(json.dumps(result, indent=2) + "\n")
    _plot(trace, out / "tracking.png", scenario.spec.name)
    lines = [
        f"# {scenario.spec.name}: {scenario.spec.method.name}",
        "",
        scenario.spec.description.strip(),
        "",
        "| metric | value |",
        "|---|---|",
        *(f"| {k} | {_fmt(v)} |" for k, v in metrics.items()),
        "",
        "![tracking](tracking.png)",
        "",
    ]
    if trace.events:
        lines += ["## Events", ""] + [f"- t = {t:.3f} s: {m}" for t, m in trace.events]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return metrics


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _plot(trace: Trace, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for i, axis in enumerate("xyz"):
        axes[0].plot(trace.t, trace.goal_position[:, i], "--", label=f"goal {axis}")
        axes[0].plot(trace.t, trace.ee_position[:, i], label=f"end effector {axis}")
    axes[0].set_ylabel("position [m]")
    axes[0].legend(ncol=3, fontsize=7)
    axes[1].plot(trace.t, trace.position_error * 100, label="position error [cm]")
    axes[1].plot(
        trace.t, np.rad2deg(trace.rotation_error), label="rotation error [deg]"
    )
    axes[1].legend(fontsize=7)
    axes[1].set_ylabel("error")
    axes[2].plot(trace.t, trace.q)
    axes[2].set_ylabel("joints [rad]")
    axes[2].set_xlabel("time [s]")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
