# SPDX-License-Identifier: Apache-2.0
"""Plots in the style of the CAT paper's figures, one or several methods each.

* ``tracking.png``: distance from the start pose over time, for the goal and
  for each method's end effector (Figs. 4-6);
* ``errors.png``: position and orientation error to the goal over time;
* ``contact_force.png``: sum of contact normal forces over time.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cbp.trace import RunTrace

__all__ = ["METHOD_COLORS", "plot_runs"]

#: One color per method across every figure (as in the paper).
METHOD_COLORS = {
    "cat": "tab:blue",
    "ik": "tab:green",
    "mp": "tab:orange",
    "jt": "tab:red",
    "kinematic": "tab:purple",
}


def plot_runs(traces: Mapping[str, RunTrace], out: Path, title: str) -> list[Path]:
    """Write the three figures for ``traces`` (by method) into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    first = next(iter(traces.values()))
    start = first.ee_position[0]
    paths = []

    fig, ax = plt.subplots(figsize=(8, 4))
    goal_distance = np.linalg.norm(first.goal_position - start, axis=1)
    ax.plot(first.t, goal_distance, "k--", label="goal")
    for name, trace in traces.items():
        distance = np.linalg.norm(trace.ee_position - start, axis=1)
        ax.plot(trace.t, distance, color=METHOD_COLORS.get(name), label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("distance from start [m]")
    ax.set_title(f"{title}: tracking")
    ax.legend()
    ax.grid(alpha=0.3)
    paths.append(_save(fig, out / "tracking.png"))

    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for name, trace in traces.items():
        color = METHOD_COLORS.get(name)
        axes[0].plot(trace.t, trace.position_error * 100, color=color, label=name)
        axes[1].plot(trace.t, np.rad2deg(trace.rotation_error), color=color, label=name)
    axes[0].set_ylabel("position error [cm]")
    axes[1].set_ylabel("orientation error [deg]")
    axes[1].set_xlabel("time [s]")
    axes[0].legend()
    for a in axes:
        a.grid(alpha=0.3)
    axes[0].set_title(f"{title}: error to the goal")
    paths.append(_save(fig, out / "errors.png"))

    fig, ax = plt.subplots(figsize=(8, 3))
    for name, trace in traces.items():
        ax.plot(trace.t, trace.contact_force, color=METHOD_COLORS.get(name), label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("contact force [N]")
    ax.set_title(f"{title}: contact force, robot and scene")
    ax.legend()
    ax.grid(alpha=0.3)
    paths.append(_save(fig, out / "contact_force.png"))
    return paths


def _save(fig: object, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()  # type: ignore[attr-defined]
    fig.savefig(path, dpi=100)  # type: ignore[attr-defined]
    plt.close(fig)  # type: ignore[arg-type]
    return path
