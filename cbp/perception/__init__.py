# SPDX-License-Identifier: Apache-2.0
"""Perception: a simulated depth camera, an occupancy grid, map updates off-loop."""

from cbp.perception.spec import CameraSpec, PerceptionSpec

__all__ = ["CameraSpec", "PerceptionSpec"]
