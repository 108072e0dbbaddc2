# SPDX-License-Identifier: Apache-2.0
"""Constraint ``self_collision``: two links may not move into each other."""

from __future__ import annotations

from typing import ClassVar

from cbp.collision.contacts import ContactSet
from cbp.collision.world import CollisionWorld
from cbp.errors import ConfigError

from .contact_normals_constraint import ContactNormalsConstraint


class SelfCollisionConstraint(ContactNormalsConstraint):
    r"""Pairs of robot links may not move further into each other.

    For each pair of robot shapes closer than the activation distance, with
    witness points :math:`p` and :math:`p'`, normal :math:`n` from :math:`p'`
    toward :math:`p` and signed distance :math:`d` (both paddings included):

    .. math:: n^T (J_p - J_{p'}) \Delta q \ge -k (d - d_{safe})

    The checked pairs are the collision world's (adjacent links and robot.yaml's
    ``ignore_pairs`` excluded). Parameters as ``contact_normals``.
    """

    type_name: ClassVar[str] = "self_collision"

    def attach_world(self, world: CollisionWorld) -> None:
        """Take self contacts from ``world`` (which must query them)."""
        if not world.settings.self_collision:
            raise ConfigError(
                f"{self.name} ({self.type_name}) needs 'collision.self_collision: true'"
            )
        super().attach_world(world)

    def _select(self, contacts: ContactSet) -> ContactSet:
        return contacts.self_part()
