# SPDX-License-Identifier: Apache-2.0
"""Outputs of a run: trace.csv, metrics.json, plots and report.md.

The kinematic executor's outputs (:func:`write_outputs`) and those of the
simulated executors, one or several methods (:func:`write_runs`).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from cbp.executors.settings import VelocitySettings
from cbp.metrics import kinematic_metrics, orbit_metrics, run_metrics
from cbp.plots import plot_orbit, plot_runs
from cbp.robot import FloatArray
from cbp.scenario.runtime import Scenario
from cbp.trace import KinematicTrace, RunTrace, VelocityTrace


def write_outputs(
    scenario: Scenario, trace: KinematicTrace, out: Path
) -> dict[str, Any]:
    """Write trace.csv, metrics.json, tracking.png and report.md into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    stream = scenario.goal_stream()
    metrics = kinematic_metrics(
        trace, scenario.robot, stream.end_time if stream is not None else 0.0
    )
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
    _write_report(
        out,
        scenario,
        scenario.spec.method.name,
        metrics,
        [out / "tracking.png"],
        trace.events,
    )
    return metrics


def _write_report(
    out: Path,
    scenario: Scenario,
    method: str,
    metrics: Mapping[str, Any],
    figures: list[Path],
    events: list[tuple[float, str]],
) -> None:
    """report.md of one run: description, metrics table, figures, events."""
    lines = [
        f"# {scenario.spec.name}: {method}",
        "",
        scenario.spec.description.strip(),
        "",
        "| metric | value |",
        "|---|---|",
        *(f"| {k} | {_fmt(v)} |" for k, v in metrics.items()),
        "",
        *(f"![{p.stem}]({p.name})" for p in figures),
        "",
    ]
    if events:
        lines += ["## Events", ""] + [f"- t = {t:.3f} s: {m}" for t, m in events]
    (out / "report.md").write_text("\n".join(lines) + "\n")


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _plot(trace: KinematicTrace, path: Path, title: str) -> None:
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


# ---------------------------------------------------------------- simulated runs


def write_runs(
    scenario: Scenario, traces: Mapping[str, RunTrace], out: Path
) -> dict[str, dict[str, Any]]:
    """Write the outputs of simulated runs (one or several methods) into ``out``.

    ``trace.csv`` (``trace_<method>.csv`` when there are several methods),
    ``metrics.json`` (one object per method under its name, with its events),
    ``tracking.png``, ``errors.png``, ``contact_force.png`` and ``report.md``.

    Returns:
        The metrics, by method.
    """
    out.mkdir(parents=True, exist_ok=True)
    metrics = {name: run_metrics(trace) for name, trace in traces.items()}
    for name, trace in traces.items():
        csv_name = "trace.csv" if len(traces) == 1 else f"trace_{name}.csv"
        _write_run_csv(trace, out / csv_name)
    document = {
        name: {
            **metrics[name],
            "events": [{"t": t, "message": m} for t, m in tr.events],
        }
        for name, tr in traces.items()
    }
    (out / "metrics.json").write_text(json.dumps(document, indent=2) + "\n")
    figures = plot_runs(traces, out, scenario.spec.name)
    keys = list(next(iter(metrics.values())))
    lines = [
        f"# {scenario.spec.name}: {', '.join(traces)}",
        "",
        scenario.spec.description.strip(),
        "",
        "| metric | " + " | ".join(traces) + " |",
        "|---|" + "---|" * len(traces),
        *(
            f"| {key} | " + " | ".join(_fmt(metrics[m][key]) for m in traces) + " |"
            for key in keys
        ),
        "",
        *(f"![{f.stem}]({f.name})" for f in figures),
        "",
    ]
    for name, trace in traces.items():
        if trace.events:
            lines += [f"## Events: {name}", ""]
            lines += [f"- t = {t:.3f} s: {m}" for t, m in trace.events[:50]]
            if len(trace.events) > 50:
                lines.append(f"- ... {len(trace.events) - 50} more in metrics.json")
            lines.append("")
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return metrics


def _write_run_csv(trace: RunTrace, path: Path) -> None:
    n = trace.q.shape[1]
    header = ["t"]
    for who in ("goal", "ee"):
        header += [f"{who}_{c}" for c in ("x", "y", "z", "qx", "qy", "qz", "qw")]
    header += [f"q{i}" for i in range(n)]
    header += ["contact_force", "wrist_force", "penetration", "clearance"]
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for i in range(trace.t.size):
            row = [f"{trace.t[i]:.4f}"]
            for p, R in (
                (trace.goal_position[i], trace.goal_rotation[i]),
                (trace.ee_position[i], trace.ee_rotation[i]),
            ):
                row += [f"{v:.6f}" for v in p]
                row += [f"{v:.6f}" for v in _quaternion(R)]
            row += [f"{v:.6f}" for v in trace.q[i]]
            row += [
                f"{trace.contact_force[i]:.4f}",
                f"{trace.wrist_force[i]:.4f}",
                f"{trace.penetration[i]:.6f}",
                f"{trace.clearance[i]:.6f}",
            ]
            writer.writerow(row)


def _quaternion(R: FloatArray) -> FloatArray:
    """(x, y, z, w) of a rotation matrix; NaN if it is not finite."""
    if not np.all(np.isfinite(R)):
        return np.full(4, np.nan)
    q = pin.Quaternion(np.asarray(R))
    return np.array([q.x, q.y, q.z, q.w])


# ---------------------------------------------------------------- velocity runs


def write_velocity_run(
    scenario: Scenario, trace: VelocityTrace, out: Path, method: str = "velocity"
) -> dict[str, Any]:
    """Write a velocity-executor run: trace.csv, metrics.json, the orbit figures."""
    out.mkdir(parents=True, exist_ok=True)
    metrics = orbit_metrics(
        trace, scenario.spec.method.settings(VelocitySettings).transient_s
    )
    robot = scenario.robot
    v_labels = ["base_vx", "base_vy", "base_wz", *robot.joint_names[1:]]
    q_labels = ["base_x", "base_y", "base_cos", "base_sin", *robot.joint_names[1:]]
    signals = trace.signals
    with open(out / "trace.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["t", *q_labels, *(f"u_{n}" for n in v_labels), *signals])
        for i in range(trace.t.size):
            writer.writerow(
                [f"{trace.t[i]:.4f}"]
                + [f"{v:.6f}" for v in trace.q[i]]
                + [f"{v:.6f}" for v in trace.u[i]]
                + [f"{signals[k][i]:.6f}" for k in signals]
            )
    document = {
        method: {
            **metrics,
            "events": [{"t": t, "message": m} for t, m in trace.events],
        }
    }
    (out / "metrics.json").write_text(json.dumps(document, indent=2) + "\n")
    figures = plot_orbit(trace.t, signals, trace.u, v_labels, out, scenario.spec.name)
    _write_report(out, scenario, method, metrics, figures, trace.events)
    return metrics
