# SPDX-License-Identifier: Apache-2.0
"""Plots in the style of the papers' figures.

CAT paper, one or several methods each (:func:`plot_runs`):

* ``tracking.png``: distance from the start pose over time, for the goal and
  for each method's end effector (Figs. 4-6);
* ``errors.png``: position and orientation error to the goal over time;
* ``contact_force.png``: sum of contact normal forces over time.

Orbit paper, one run (:func:`plot_orbit`): distance, view error, roll,
altitude, obstacle distance and velocities over time.

Each figure is drawn when the traces have its columns (:class:`~cbp.trace.Trace`),
in :func:`readable_axes` style.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import ParamSpec, TypeVar

import numpy as np

from cbp.methods import method_colour
from cbp.robot import FloatArray
from cbp.trace import Trace

__all__ = ["colour", "plot_orbit", "plot_runs", "readable_axes"]

P = ParamSpec("P")
R = TypeVar("R")


def readable_axes(draw: Callable[P, R]) -> Callable[P, R]:
    """Decorate a function that draws figures: readable tick labels in them.

    Tick labels show the values themselves: no "+1.000e3" offset and no "1e-5"
    factor above an axis (a reader cannot apply them in their head); decimals
    are written out down to 1e-9 and up to 1e9.
    """

    @functools.wraps(draw)
    def styled(*args: P.args, **kwargs: P.kwargs) -> R:
        import matplotlib

        with matplotlib.rc_context(
            {"axes.formatter.useoffset": False, "axes.formatter.limits": (-9, 9)}
        ):
            return draw(*args, **kwargs)

    return styled


def colour(method: str) -> tuple[float, float, float]:
    """Method ``method``'s colour (the method table's) as matplotlib takes it."""
    r, g, b = method_colour(method)
    return (r / 255.0, g / 255.0, b / 255.0)


@readable_axes
def plot_runs(traces: Mapping[str, Trace], out: Path, title: str) -> list[Path]:
    """Write the figures ``traces`` (by method) have columns for into ``out``.

    With a goal: ``tracking.png`` and ``errors.png``; with the simulator's
    contact forces: ``contact_force.png``; with reported signals: the orbit
    figures (:func:`plot_orbit`); one run without signals: ``joints.png``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths: list[Path] = []
    if any(trace.has_goal for trace in traces.values()):
        paths += _plot_tracking(traces, out, title)
    if any(trace.contact_force is not None for trace in traces.values()):
        fig, ax = plt.subplots(figsize=(8, 3))
        for name, trace in traces.items():
            if trace.contact_force is not None:
                ax.plot(
                    trace.t,
                    trace.contact_force,
                    color=colour(name),
                    label=name,
                )
        ax.set_xlabel("time [s]")
        ax.set_ylabel("contact force [N]")
        ax.set_title(f"{title}: contact force, robot and scene")
        ax.legend()
        ax.grid(alpha=0.3)
        paths.append(_save(fig, out / "contact_force.png"))
    if len(traces) == 1:
        (trace,) = traces.values()
        if trace.signals:
            paths += plot_orbit(trace, out, title)
        else:
            paths.append(
                _plot_columns(
                    trace.t,
                    trace.q,
                    _labels(trace.q_names, trace.q.shape[1], "q"),
                    "joint position [rad or m]",
                    f"{title}: joints",
                    out / "joints.png",
                )
            )
    return paths


def _plot_columns(
    t: FloatArray,
    values: FloatArray,
    labels: list[str],
    ylabel: str,
    title: str,
    path: Path,
) -> Path:
    """One line per column of ``values`` over ``t``."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    for i, label in enumerate(labels):
        ax.plot(t, values[:, i], label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(ncol=4, fontsize=7)
    ax.grid(alpha=0.3)
    return _save(fig, path)


def _plot_tracking(traces: Mapping[str, Trace], out: Path, title: str) -> list[Path]:
    """tracking.png (distance from the start pose) and errors.png."""
    import matplotlib.pyplot as plt

    first = next(iter(traces.values()))
    start = first.ee_position[0]
    fig, ax = plt.subplots(figsize=(8, 4))
    goal_distance = np.linalg.norm(first.goal_position - start, axis=1)
    ax.plot(first.t, goal_distance, "k--", label="goal")
    for name, trace in traces.items():
        distance = np.linalg.norm(trace.ee_position - start, axis=1)
        ax.plot(trace.t, distance, color=colour(name), label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("distance from start [m]")
    ax.set_title(f"{title}: tracking")
    ax.legend()
    ax.grid(alpha=0.3)
    paths = [_save(fig, out / "tracking.png")]

    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for name, trace in traces.items():
        color = colour(name)
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
    return paths


def _labels(names: list[str], n: int, prefix: str) -> list[str]:
    """Column labels: the names when there is one per column, else q0, q1, ..."""
    return names if len(names) == n else [f"{prefix}{i}" for i in range(n)]


def _save(fig: object, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()  # type: ignore[attr-defined]
    fig.savefig(path, dpi=100)  # type: ignore[attr-defined]
    plt.close(fig)  # type: ignore[arg-type]
    return path


@readable_axes
def plot_orbit(trace: Trace, out: Path, title: str) -> list[Path]:
    """The orbit paper's figures (Figs. 7-18) for one run, as far as it has them.

    ``distance.png`` (r(t) and r_d), ``orientation.png`` (view error),
    ``roll.png``, ``altitude.png`` (h(t) and z_min), ``obstacle.png`` (g(t) and
    r_r) and, with commanded velocities, ``velocities.png``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, signals = trace.t, trace.signals
    panels = [
        ("distance.png", "distance", "distance_desired", "r(t)", "r_d", "[m]"),
        ("orientation.png", "view_error_deg", None, "view error", None, "[deg]"),
        ("roll.png", "roll_deg", None, "roll about the line of sight", None, "[deg]"),
        ("altitude.png", "altitude", "min_altitude", "h(t)", "z_min", "[m]"),
        (
            "obstacle.png",
            "obstacle_distance",
            "min_obstacle_distance",
            "g(t)",
            "r_r",
            "[m]",
        ),
    ]
    paths = []
    for name, key, bound, label, bound_label, unit in panels:
        if key not in signals:
            continue
        fig, ax = plt.subplots(figsize=(8, 3))
        ax.plot(t, signals[key], label=label)
        if bound is not None and bound in signals:
            ax.plot(t, signals[bound], "k--", label=bound_label)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"{label} {unit}")
        ax.set_title(f"{title}: {label}")
        ax.legend()
        ax.grid(alpha=0.3)
        paths.append(_save(fig, out / name))
    if trace.u is not None:
        paths.append(
            _plot_columns(
                t,
                trace.u,
                _labels(trace.v_names, trace.u.shape[1], "v"),
                "velocity [m/s or rad/s]",
                f"{title}: base and joint velocities",
                out / "velocities.png",
            )
        )
    return paths
