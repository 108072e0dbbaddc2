# SPDX-License-Identifier: Apache-2.0
"""Declared objects that appear or move: a collision world kept up to date.

A scenario's ``world.objects`` may appear during a run (``appear_at``) or move
(``motion``). The simulators move their bodies; :class:`DeclaredObjects`
gives a collision world the objects where their timelines put them, with
their velocities, for the executors that plan against declared objects.
"""

from __future__ import annotations

from cbp.collision.objects import PrimitiveEnvironment
from cbp.collision.world import CollisionWorld
from cbp.robot import FloatArray
from cbp.run.events import RunLog
from cbp.run.separation import DeclaredSeparationMonitor
from cbp.scenario.runtime import Scenario
from cbp.scenario.scene import ObjectSpec

__all__ = ["DeclaredObjects", "ObjectKey", "object_key"]

#: Which of some objects are in the scene at a time, where, and how they move.
ObjectKey = tuple[tuple[bool, tuple[float, ...], tuple[float, ...]], ...]


def object_key(objects: list[ObjectSpec], t: float) -> ObjectKey:
    """Which of ``objects`` are present at ``t``, where, and how they move then.

    Equal keys: nothing changed (an object that stops keeps its place but not
    its velocity).
    """
    return tuple(
        (
            o.present(t),
            tuple(o.placement_at(t).translation),
            tuple(o.velocity_at(t)),
        )
        for o in objects
    )


class DeclaredObjects:
    """Keeps a collision world's declared objects where their timelines put them.

    Args:
        scenario: the scenario whose ``world.objects`` are followed.
        world: the collision world to update (the scenario's).
        log: where :meth:`watch` says when a moving object comes nearer than
            the arm can keep from (none: not watched).

    Moving objects are measured ``look_ahead`` seconds ahead along their
    velocity (:class:`~cbp.collision.objects.PrimitiveEnvironment`) unless the
    scenario sets ``collision.predict_motion: false``.
    """

    def __init__(
        self, scenario: Scenario, world: CollisionWorld, log: RunLog | None = None
    ) -> None:
        """Start from the objects as they are at time 0 (the world's now)."""
        self.scenario = scenario
        self.world = world
        self.dynamic = [o for o in scenario.spec.world.objects if o.dynamic]
        self._predict = scenario.spec.collision.predict_motion
        self._key = object_key(self.dynamic, 0.0)
        moves = any(o.motion is not None for o in self.dynamic)
        #: Speed and separation with the moving objects (None: not watched).
        self.separation = (
            DeclaredSeparationMonitor(world, log)
            if log is not None and moves and self._predict
            else None
        )

    def watch(self, t: float, q: FloatArray, reaction: float) -> None:
        """Say when a moving object comes nearer than the arm at ``q`` can keep from.

        ``reaction``: how long the robot takes to begin answering [s].
        """
        if self.separation is not None:
            self.separation.check(t, q, reaction)

    def update(self, t: float, look_ahead: float = 0.0) -> list[str]:
        """Give the world the objects as they are at ``t`` [s], if any changed.

        Returns:
            The names of the objects that appeared since the last update.
        """
        key = object_key(self.dynamic, t)
        if key == self._key:
            return []
        appeared = [
            obj.name
            for obj, now, then in zip(self.dynamic, key, self._key, strict=True)
            if now[0] and not then[0]
        ]
        self._key = key
        self.world.set_environment(
            PrimitiveEnvironment(
                self.scenario.environment_objects(t),
                look_ahead if self._predict else 0.0,
            )
        )
        return appeared
