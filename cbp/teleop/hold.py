# SPDX-License-Identifier: Apache-2.0
"""Why the arm holds short of the operator's goal: one state, from what a page sees.

:func:`hold_reason` is a pure function of :class:`HoldFacts` (the session's
snapshot, where the goal lies, whether the arm has stopped short of it); the
goal page shows its answer as a state that stays while the arm holds, so that
a flood of other events cannot push the reason out of sight.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = [
    "DEADLINE_HOLDS",
    "HOLDS",
    "GoalSpace",
    "Hold",
    "HoldFacts",
    "hold_reason",
]

#: Deadline misses within the last second from which planning counts as what
#: holds the arm (a missed period's plan is discarded; at 30-60 periods a second).
DEADLINE_HOLDS = 5

#: Where the goal lies: open space, an obstacle, or space no camera has seen.
GoalSpace = Literal["free", "obstacle", "unseen"]

#: Each kind of hold and what the page says of it.
HOLDS: dict[str, str] = {
    "paused": "paused: the operator holds the arm",
    "perception": "the cameras hold the arm",
    "goal in obstacle": "the goal lies inside an obstacle",
    "goal in unseen space": "the goal lies in space no camera has seen",
    "out of reach": "the goal is out of the arm's reach",
    "deadline": "planning misses its deadlines (the machine is too slow now)",
    "contact": "an obstacle is in the way (red arrows: the blocked directions)",
    "joint limit": "a joint is at its limit",
    "self-collision": "the arm would hit itself",
    "held": "a constraint holds the arm",
    "stopped short": "the arm stops short of the goal",
}


@dataclass(frozen=True)
class Hold:
    """Why the arm holds.

    Attributes:
        kind: a key of :data:`HOLDS`.
        text: what the page says (the kind's text, with details).
    """

    kind: str
    text: str


@dataclass(frozen=True)
class HoldFacts:
    """What the reason is read from.

    Attributes:
        paused: the operator paused the session.
        short: the arm has stopped short of the goal (its trajectory ends
            short of it, where the hand already is, for a while).
        goal_space: where the goal the arm goes for lies.
        clamped: what bounded the goal (the world's box, the arm's reach), or
            None.
        held_by: the kinds of hard constraint active at the planner's last
            step (:attr:`cbp.teleop.Snapshot.held_by`).
        note: the last command period's note.
        recent_misses: deadline misses in the last second.
        method: the method in control.
    """

    paused: bool = False
    short: bool = False
    goal_space: GoalSpace = "free"
    clamped: str | None = None
    held_by: frozenset[str] = frozenset()
    note: str = ""
    recent_misses: int = 0
    method: str = "cat"


def hold_reason(facts: HoldFacts) -> Hold | None:
    """Why the arm holds, or None while it follows the goal (or has reached it).

    In order: the operator's pause; the cameras (a camera without valid
    frames, a map that lags: the period's note says "robot stopped"); then,
    once the arm has stopped short: the goal inside an obstacle, in unseen
    space, or bounded (out of reach); missed deadlines; what held the planner
    (an obstacle contact, a joint limit, the arm itself, another constraint);
    else the arm stopped short with nothing holding it (its reach, or the
    planner's own note for a method that does not say).
    """
    if facts.paused:
        return Hold("paused", HOLDS["paused"])
    if "robot stopped" in facts.note:
        return Hold("perception", f"{HOLDS['perception']}: {facts.note}")
    if not facts.short:
        return None
    if facts.goal_space == "obstacle":
        return Hold("goal in obstacle", HOLDS["goal in obstacle"])
    if facts.goal_space == "unseen":
        return Hold("goal in unseen space", HOLDS["goal in unseen space"])
    if facts.clamped is not None:
        return Hold("out of reach", f"{HOLDS['out of reach']} ({facts.clamped})")
    if facts.recent_misses >= DEADLINE_HOLDS:
        return Hold(
            "deadline",
            f"{HOLDS['deadline']}: {facts.recent_misses} in the last second",
        )
    for kind in ("contact", "joint limit", "self-collision"):
        if kind in facts.held_by:
            return Hold(kind, HOLDS[kind])
    if facts.held_by:
        names = ", ".join(sorted(facts.held_by))
        return Hold("held", f"{HOLDS['held']} ({names})")
    if facts.method in ("cat", "hybrid"):
        return Hold(
            "out of reach",
            f"{HOLDS['out of reach']}: nothing blocks it, and it gets no closer",
        )
    return Hold("stopped short", f"{HOLDS['stopped short']} ({facts.note})")
