# SPDX-License-Identifier: Apache-2.0
"""The ``collision:`` section of a scenario: contact queries and step validation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from cbp.errors import ConfigError

__all__ = ["MAX_CONTACTS_PER_LINK", "CollisionSettings"]

#: Most contacts kept per robot shape (each is a row of every contact query).
MAX_CONTACTS_PER_LINK = 64


@dataclass(frozen=True, kw_only=True)
class CollisionSettings:
    """The ``collision:`` section of a scenario."""

    activation_distance: float = 0.05
    """Obstacles closer than this (after padding) produce contacts [m]."""
    contacts_per_link: int = 3
    """Contacts kept per robot shape: the closest, spread over directions."""
    self_collision: bool = True
    """Also query the robot's own shape pairs."""
    padding: float | None = None
    """Distance added around the links [m]; default: robot.yaml's."""
    predict_motion: bool = True
    """Plan against declared objects that move (``motion:``) where they will be
    when the plan runs: measured ahead along their velocity by two command
    periods and the robot's stopping time from top speed (the trajectory
    executors), or a tick and that stopping time (the velocity executor)
    (:class:`~cbp.collision.objects.PrimitiveEnvironment`'s ``look_ahead``).
    False: where they are now, as an occupancy map sees them (it has no
    velocities)."""
    narrow_phase: Literal["compiled", "coal"] = "compiled"
    """How distances to declared objects and between the robot's own shapes
    are measured: ``compiled``, GJK and EPA in one compiled pass over the pairs
    the broad phase keeps; ``coal``, coal's distance called from Python per
    pair (the reference, slower). Non-convex meshes are measured by coal
    either way."""
    penetration_tolerance: float = 0.005
    """Step validation rejects a step that penetrates deeper than this [m]
    (plus half a cell against an occupancy map, whose surfaces are only known
    to that resolution)."""

    def __post_init__(self) -> None:
        """Positive distances and counts."""
        if not self.activation_distance > 0:
            raise ConfigError(
                f"must be > 0, got {self.activation_distance}", "activation_distance"
            )
        if not 1 <= self.contacts_per_link <= MAX_CONTACTS_PER_LINK:
            raise ConfigError(
                f"must be in [1, {MAX_CONTACTS_PER_LINK}], got "
                f"{self.contacts_per_link}",
                "contacts_per_link",
            )
        if self.padding is not None and not self.padding >= 0:
            raise ConfigError(f"must be >= 0, got {self.padding}", "padding")
        if not self.penetration_tolerance >= 0:
            raise ConfigError(
                f"must be >= 0, got {self.penetration_tolerance}",
                "penetration_tolerance",
            )
