# SPDX-License-Identifier: Apache-2.0
"""PyBullet simulation: the scene built from a scenario's declarations."""

from cbp.sim.scene import PybulletScene

__all__ = ["PybulletScene"]
