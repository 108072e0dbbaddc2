# SPDX-License-Identifier: Apache-2.0
"""What a planner's IK search tells the run: a failure, once per episode.

IK and MP hold the arm while their search finds no collision-free
configuration for the goal, and ask again every period; :class:`SearchEvents`
says so once per episode of failure, with the reason (out of reach, in an
obstacle, unseen space) and, when the run ends, the count.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pinocchio as pin

if TYPE_CHECKING:
    from cbp.run.parts import RunParts
    from cbp.scenario.reach import Reach

__all__ = ["REPORT_AFTER", "SearchEvents"]


#: A goal the search has not solved for this long [s] is reported even when
#: every search was cut short by the period's budget.
REPORT_AFTER = 1.0


class SearchEvents:
    """The run's events for a planner's IK search: once per episode of failure.

    A planner that needs a collision-free configuration for the goal (IK, MP)
    holds the arm while the search finds none, and asks again every period (the
    map may change, the goal may move). Without an event the run would only
    show an arm that does not move; this says so once per episode of failure,
    however often the goal moves during it: as soon as a search ends without a
    solution, or after :data:`REPORT_AFTER` of searches cut short by the
    budget, or at once for a goal beyond the arm's reach
    (:mod:`cbp.scenario.reach`). It names the likely reason: out of reach, or
    space no camera has seen counting as an obstacle. The reason changing
    during the episode is said again; when a solution is found (or the run
    ends first), an event says so with the number of periods without one.

    Args:
        method: the planner's name, for the messages.
    """

    def __init__(self, method: str) -> None:
        """No failure reported yet."""
        self.method = method
        self._since: float | None = None  # the episode's first failure [s]
        self._periods = 0  # periods without a solution in the episode
        self._said: str | None = None  # the reason said in the episode
        self._run: RunParts | None = None  # the run the episode is in
        self._reach: tuple[RunParts, Reach | None] | None = None  # per run

    def failed(self, run: RunParts, goal: pin.SE3, exhausted: bool) -> None:
        """No solution for ``goal`` this period; ``exhausted``: every start tried."""
        t = run.arm.t
        if self._since is None or self._run is not run:
            self._since, self._periods, self._said, self._run = t, 0, None, run
        self._periods += 1
        beyond = self.beyond_reach(run, goal)
        perception = run.scenario.spec.perception
        unseen = perception.source == "depth_camera" and perception.unknown_blocks
        # The kind of reason, not its numbers: a goal that moves out of reach
        # is said once, not once per distance.
        reason = "reach" if beyond is not None else "unseen" if unseen else ""
        if reason == self._said:
            return  # said already in this episode
        waited = t - self._since
        if self._said is None and not (
            beyond is not None or exhausted or waited >= REPORT_AFTER
        ):
            return
        self._said = reason
        if beyond is not None:
            what = f"no IK solution for the goal, out of reach: {beyond}"
        else:
            how = (
                ""
                if exhausted
                else f" in {waited:.1f} s of searches cut short by the period's budget"
            )
            why = (
                "; space no camera has seen counts as an obstacle "
                "(perception.unknown: occupied), and the goal's configurations "
                "may pass through it until a camera sees that space"
                if unseen
                else ""
            )
            what = f"no collision-free IK solution for the goal{how}{why}"
        run.event(
            t,
            f"{self.method}: {what}; the arm holds, and the search is tried again "
            "each period (said once until a solution is found)",
        )

    def beyond_reach(self, run: RunParts, goal: pin.SE3) -> str | None:
        """Why ``goal`` is beyond the arm's reach, or None when it may be within it."""
        if self._reach is None or self._reach[0] is not run:
            self._reach = (run, run.scenario.reach())
        reach = self._reach[1]
        return None if reach is None else reach.beyond(goal.translation)

    def solved(self, run: RunParts) -> None:
        """The search found a solution (after a reported failure: say so)."""
        self._end(run, "a collision-free IK solution found")

    def close(self) -> None:
        """The run ends: a reported failure that lasts to the end says how long."""
        self._end(self._run, "still no IK solution at the end of the run")

    def _end(self, run: RunParts | None, what: str) -> None:
        """End the episode; one reported in ``run`` is said to end with ``what``."""
        if self._said is not None and run is not None and self._run is run:
            run.event(
                run.arm.t,
                f"{self.method}: {what}, after {self._failures()} without one",
            )
        self._since, self._periods, self._said, self._run = None, 0, None, None

    def _failures(self) -> str:
        """The episode's length: its periods without a solution and its time."""
        run, since = self._run, self._since
        seconds = 0.0 if run is None or since is None else run.arm.t - since
        periods = "period" if self._periods == 1 else "periods"
        return f"{self._periods} {periods} ({seconds:.1f} s)"
