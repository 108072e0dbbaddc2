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

    Moving objects are measured ``look_ahead`` seconds ahead along their
    velocity (:class:`~cbp.collision.objects.PrimitiveEnvironment`) unless the
    scenario sets ``collision.predict_motion: false``.
    """

    def __init__(self, scenario: Scenario, world: CollisionWorld) -> None:
        """Start from the objects as they are at time 0 (the world's now)."""
        self.scenario = scenario
        self.world = world
        self.dynamic = [o for o in scenario.spec.world.objects if o.dynamic]
        self._predict = scenario.spec.collision.predict_motion
        self._key = object_key(self.dynamic, 0.0)

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
