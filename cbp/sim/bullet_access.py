# SPDX-License-Identifier: Apache-2.0
"""PyBullet's names on a simulation: ``scene`` and ``client``, PyBullet only.

Code written for PyBullet reads them (a depth camera on ``client``, a body of
``scene``); a simulation on another engine says to use its physics instead.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cbp.sim.bullet_physics import BulletMobilePhysics, BulletPhysics
    from cbp.sim.scene import PybulletScene

__all__ = ["PybulletAccess"]


class PybulletAccess:
    """``scene`` and ``client`` of a simulation whose engine is PyBullet's.

    What code written for PyBullet reads (a camera on ``client``, a body of
    ``scene``); on another engine they say to use the simulation's physics.
    """

    physics: object
    simulator: str

    @property
    def scene(self) -> PybulletScene:
        """The PyBullet scene (client, body ids); PyBullet only."""
        return self._bullet().scene

    @property
    def client(self) -> int:
        """The PyBullet client id; PyBullet only."""
        return int(self._bullet().client)

    def _bullet(self) -> BulletPhysics | BulletMobilePhysics:
        from cbp.sim.bullet_physics import BulletMobilePhysics, BulletPhysics

        if not isinstance(self.physics, BulletPhysics | BulletMobilePhysics):
            raise AttributeError(
                f"this simulation runs on {self.simulator}, not PyBullet: "
                f"use its physics ({type(self).__name__}.physics)"
            )
        return self.physics
