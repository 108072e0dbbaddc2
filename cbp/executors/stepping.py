# SPDX-License-Identifier: Apache-2.0
"""One validated engine step: the inner loop of the kinematic and CAT executors.

A step is the engine's answer for ``dt`` from ``q`` (already checked by the
engine's step guard), integrated, and validated against the collision world
(CAT Sec. IV-C): a step that ends deeper in collision than
``collision.penetration_tolerance``, and deeper than where it started, is not
taken; the contacts found where it would have ended constrain the next try
(:meth:`~cbp.collision.world.CollisionWorld.try_step`). A step the engine cannot
solve is not taken either. The caller decides what not taking a step means for
its loop (hold the robot, end a path) and how to word it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from cbp.collision.world import CollisionWorld
from cbp.engine import Engine, StepResult
from cbp.errors import PluginOutputError, SolveError
from cbp.robot import FloatArray
from cbp.run.events import Repeating

__all__ = ["Step", "ValidatedStepper"]


@dataclass(frozen=True)
class Step:
    """What :meth:`ValidatedStepper.step` did.

    Attributes:
        outcome: ``taken``; ``failed`` (the engine gave no safe answer); or
            ``rejected`` (step validation refused where it ended).
        q: the configuration after the step: the new one when taken, the
            starting one otherwise.
        dq: the engine's tangent step, None when it failed.
        penetration: the padded shapes' penetration at ``q`` [m] (0 without a
            collision world); for a rejected step, where it would have ended.
        reason: why it was not taken.
    """

    outcome: Literal["taken", "failed", "rejected"]
    q: FloatArray
    dq: FloatArray | None
    penetration: float
    reason: str = ""

    @property
    def taken(self) -> bool:
        """The robot moved to the new configuration."""
        return self.outcome == "taken"


class ValidatedStepper:
    """Engine steps checked against an optional collision world.

    Args:
        engine: the QP engine.
        world: the collision world that validates steps, or None (no check).
        event: records a message at a time (the run's events): when the
            engine eases the QP, once per episode with a count
            (:class:`~cbp.run.events.Repeating`).
        now: the run's time [s], for the events.

    Attributes:
        last: what the engine's last solved step returned, or None.
    """

    def __init__(
        self,
        engine: Engine,
        world: CollisionWorld | None,
        event: Callable[[float, str], None],
        now: Callable[[], float],
    ) -> None:
        """Keep the parts; the starting penetration is set by :meth:`start`."""
        self.engine = engine
        self.world = world
        self.now = now
        self.eased = Repeating(event, "QP eased")
        self.depth = 0.0
        self.last: StepResult | None = None

    def start(self, q: FloatArray) -> None:
        """Begin from ``q``: its penetration is the depth a step may back out of."""
        self.depth = self.world.check(q).penetration if self.world is not None else 0.0

    def step(self, q: FloatArray, dt: float) -> Step:
        """One step of ``dt`` from ``q``; see the module docstring."""
        engine = self.engine
        try:
            result = engine.step(q, dt)
        except (SolveError, PluginOutputError) as exc:
            return Step("failed", q, None, self.depth, str(exc))
        self.last = result
        if result.eased is not None:
            self.eased.happened(self.now(), result.eased.description)
        dq = result.dq
        robot = engine.robot
        # q + dq is pinocchio's integration on a Euclidean model, without its call.
        q_next = q + dq if robot.is_euclidean else robot.integrate(q, dq)
        if self.world is None:
            return Step("taken", q_next, dq, 0.0)
        check = self.world.try_step(q_next, self.depth)
        if not check.accepted:
            return Step(
                "rejected",
                q,
                dq,
                check.penetration,
                f"penetration {check.penetration * 1e3:.1f} mm",
            )
        self.depth = check.penetration
        return Step("taken", q_next, dq, check.penetration)
