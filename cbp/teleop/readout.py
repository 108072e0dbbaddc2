# SPDX-License-Identifier: Apache-2.0
"""What the goal page says: its colours and legend, and the readout's lines.

Pure functions of a session's :class:`~cbp.teleop.Snapshot` and the hold
(:mod:`cbp.teleop.hold`), without viser: tests read them directly.
"""

from __future__ import annotations

import numpy as np

from cbp.executors.cat import HOLDING_DISTANCE
from cbp.teleop.goal_session import Snapshot
from cbp.teleop.hold import Hold

__all__ = ["LEGEND", "UNREACHABLE", "legend_html", "readout_lines"]

#: The goal counts as out of reach when the commanded trajectory ends this far
#: from it [m]: the gripper and the reachable posture are drawn.
UNREACHABLE = 0.02

#: Colours (RGB 0-255) of what the page draws; the legend names each.
ARM = (31, 120, 181)
GOAL_GRIPPER = (230, 30, 200)
CLOSEST_POSTURE = (255, 140, 0)
BLOCKED = (220, 0, 0)
PATH = (20, 20, 20)
CELLS = (200, 90, 40)

#: The legend: (colour, what it shows).
LEGEND: tuple[tuple[tuple[int, int, int], str], ...] = (
    (ARM, "the arm, where it is"),
    (GOAL_GRIPPER, "the goal, when the arm stops short of it (gripper)"),
    (CLOSEST_POSTURE, "the closest posture the arm reaches (wireframe)"),
    (BLOCKED, "blocked direction at a contact: the arm may not move along it"),
    ((120, 200, 0), "CAT's contacts, green far to red at the obstacle"),
    (PATH, "the commanded hand path"),
    ((170, 170, 170), "declared objects (translucent while the arm holds)"),
    (CELLS, "the map's occupied cells (with cameras)"),
)


def legend_html() -> str:
    """The legend as HTML: a swatch and a line per entry."""
    rows = "".join(
        '<div><span style="display:inline-block;width:0.9em;height:0.9em;'
        f"background:rgb{colour};margin-right:0.4em;vertical-align:middle"
        f'"></span>{text}</div>'
        for colour, text in LEGEND
    )
    return f'<div style="font-size:0.8em"><b>legend</b>{rows}</div>'


def readout_lines(
    snap: Snapshot, error: float, hold: Hold | None, since: float | None
) -> list[str]:
    """The readout's lines (markdown): the hold first, for as long as it lasts.

    The contact force is the simulation's (the arm touching something); the
    clearance is CAT's nearest contact's distance beyond the links' padding,
    which CAT holds at zero without the arm touching anything: said apart.
    """
    head = f"**t = {snap.t:.2f} s**, method **{snap.method}**"
    if hold is not None:
        state = f"**holds: {hold.text}**" + (
            f" (since {since:.2f} s)" if since is not None else ""
        )
    elif error < UNREACHABLE:
        state = "at the goal"
    else:
        state = "following the goal"
    force = snap.contact_force
    touching = (
        f"touching an obstacle: **yes**, {force:.1f} N"
        if force > 0.0
        else "touching an obstacle: no (contact force 0 N)"
    )
    lines = [
        head,
        "",
        state,
        "",
        f"- goal error: {error * 1e3:.0f} mm",
        f"- {touching}",
        f"- {_clearance(snap)}",
        f"- steps in the last period: {snap.steps}",
        f"- deadline misses: {snap.misses} ({snap.recent_misses} in the last second)",
    ]
    if snap.events:
        lines += ["", "latest events:"]
        lines += [f"- {t:.2f} s: {message}" for t, message in snap.events]
    return lines


def _clearance(snap: Snapshot) -> str:
    """CAT's nearest contact and how many hold the arm, as a line of text."""
    contacts = snap.contacts
    if contacts is None or not len(contacts.distance):
        return "nearest obstacle (CAT's contacts): none within reach of the links"
    nearest = round(1e3 * float(np.min(contacts.distance)), 1) + 0.0  # no -0.0
    holding = int(np.count_nonzero(contacts.distance <= HOLDING_DISTANCE))
    held = (
        f", {holding} contact{'s' if holding != 1 else ''} holding the arm (red arrows)"
        if holding
        else ""
    )
    return (
        f"nearest obstacle (CAT's contacts): {nearest:.1f} mm beyond the links' "
        f"padding{held}"
    )
