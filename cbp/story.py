# SPDX-License-Identifier: Apache-2.0
"""What happened in each run, told from its record: a sentence and a picture.

:func:`run_sentence` says in one sentence whether a method reached its goal,
how fast and with what contact, or how far short it stopped and why; the reason
comes from the run itself (the force it pressed with, the notes of the periods
in which nothing was planned, its events). :func:`plot_scene` draws the scene
from above and from the front, with each method's hand path.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cbp.metrics import CONTACT_FORCE
from cbp.plots import colour, readable_axes
from cbp.robot import FloatArray
from cbp.scenario.scene import ObjectSpec
from cbp.trace import FORCED_OFF, Trace

__all__ = ["SCENE_FIGURE", "plot_scene", "run_sentence"]

#: The picture of the scene with the hand paths, in the output folder.
SCENE_FIGURE = "scene.png"
#: The last periods looked at for why a run stopped short.
LAST_PERIODS = 30


def run_sentence(name: str, trace: Trace, metrics: Mapping[str, Any]) -> str:
    """One sentence on a run: reached in X s without contact, or why it stopped.

    Runs without a goal (the orbit scenarios) get an empty string.
    """
    if metrics.get("reached") is None or not trace.has_goal:
        return ""
    peak = metrics.get("peak_contact_force_n")
    touching = peak is not None and peak > CONTACT_FORCE
    contact = (
        f"touching the scene for {metrics['contact_duration_s']:.1f} s with up to "
        f"{peak:.1f} N"
        if touching
        else "without contact"
        if peak is not None
        else ""
    )
    forced = metrics.get("max_joint_tracking_error")
    if touching and forced is not None and forced > FORCED_OFF:
        contact += (
            f", forced up to {forced:.2f} rad off its command (an obstacle pressed "
            "the arm harder than its joints could hold)"
        )
    if metrics.get("aborted"):
        return f"**{name}** was aborted: {metrics['aborted']}."
    if metrics["reached"]:
        total = metrics.get("total_time_s")
        when = f" in {total:.1f} s" if total is not None else ""
        sentence = f"**{name}** reached the goal{when}"
        sentence += f" {contact}" if contact else ""
        clearance = metrics.get("min_clearance_m")
        if not touching and clearance is not None and np.isfinite(clearance):
            sentence += f", passing {clearance * 1e3:.0f} mm from the nearest object"
        return sentence + _misses(metrics) + "."
    error = metrics.get("final_position_error_m")
    if error is None:
        return f"**{name}** did not reach the goal" + _misses(metrics) + "."
    short = f"{error * 1e3:.0f} mm short of the goal"
    if error <= 0.01:
        angle = np.rad2deg(metrics.get("final_orientation_error_rad") or 0.0)
        short = f"at the goal's position but {angle:.0f} deg off its orientation"
    reason = _reason(trace, touching, contact)
    return f"**{name}** stopped {short}, {reason}" + _misses(metrics) + "."


def _reason(trace: Trace, touching: bool, contact: str) -> str:
    """Why a run ended short, from what it recorded."""
    if touching:
        return (
            f"pressed against the scene ({contact.removeprefix('touching the scene ')})"
        )
    held = [p.note for p in trace.periods[-LAST_PERIODS:] if not p.spliced and p.note]
    if held:
        note, count = Counter(held).most_common(1)[0]
        last = len(trace.periods[-LAST_PERIODS:])
        share = "all" if count == last else f"{count}"
        return f"because: {note} ({share} of its last {last} periods)"
    if trace.events:
        return f"after: {trace.events[-1][1]}"
    return "with no contact and no event saying why"


def _misses(metrics: Mapping[str, Any]) -> str:
    misses = metrics.get("deadline_misses") or 0
    if not misses:
        return ""
    return f"; {misses} deadline miss{'es' if misses > 1 else ''}"


@readable_axes
def plot_scene(
    objects: Sequence[ObjectSpec], traces: Mapping[str, Trace], path: Path, title: str
) -> Path:
    """The scene from above (x, y) and from the front (y, z), with the hand paths.

    Objects are drawn where they are at the start (their outline dashed when
    they appear or move later); the goal's path is dashed black; each method's
    path of the end-effector frame is a line in its colour, from a circle
    (start) to a cross (end).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    views = (
        (0, 1, "x [m]", "y [m]", "from above"),
        (1, 2, "y [m]", "z [m]", "from the front"),
    )
    first = next(iter(traces.values()))
    for ax, (i, j, xlabel, ylabel, view) in zip(axes, views, strict=True):
        for obj in objects:
            outline = _outline(obj, i, j)
            if outline is None:
                continue
            ax.fill(
                outline[:, 0],
                outline[:, 1],
                facecolor="0.8",
                edgecolor="0.4",
                linestyle="--" if obj.dynamic else "-",
            )
        goal = first.goal_position[np.all(np.isfinite(first.goal_position), axis=1)]
        if goal.size:
            ax.plot(goal[:, i], goal[:, j], "k--", linewidth=1, label="goal")
        for name, trace in traces.items():
            hand = trace.ee_position
            color = colour(name)
            ax.plot(hand[:, i], hand[:, j], color=color, label=name)
            ax.plot(hand[0, i], hand[0, j], "o", color=color, fillstyle="none")
            ax.plot(hand[-1, i], hand[-1, j], "x", color=color)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(f"{title}: {view}")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _outline(obj: ObjectSpec, i: int, j: int) -> FloatArray | None:
    """The object's outline projected on world axes (i, j), or None (a mesh)."""
    from scipy.spatial import ConvexHull

    placement = obj.placement_at(0.0)
    if obj.shape == "box":
        half = np.asarray(obj.size, dtype=float) / 2.0
        signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        local = signs * half
    elif obj.shape == "sphere":
        local = _circle(obj.size[0], 0.0)
        local = np.vstack([local, local[:, [2, 0, 1]], local[:, [1, 2, 0]]])
    elif obj.shape == "cylinder":
        radius, length = obj.size
        local = np.vstack([_circle(radius, -length / 2), _circle(radius, length / 2)])
    else:
        return None
    world = local @ placement.rotation.T + placement.translation
    points = world[:, [i, j]]
    hull = ConvexHull(points)
    return np.asarray(points[hull.vertices])


def _circle(radius: float, z: float, n: int = 32) -> FloatArray:
    """Points on a circle of ``radius`` in the plane z = ``z`` (local frame)."""
    angle = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.column_stack(
        [radius * np.cos(angle), radius * np.sin(angle), np.full(n, z)]
    )
