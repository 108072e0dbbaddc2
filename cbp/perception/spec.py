# SPDX-License-Identifier: Apache-2.0
"""The ``perception:`` section of a scenario: where the world model comes from."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from cbp.errors import ConfigError

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, kw_only=True)
class CameraSpec:
    """A depth camera fixed in the world, looking at ``target`` from ``position``."""

    position: Vec3
    """Optical centre in the world [m]."""
    target: Vec3
    """A point on the optical axis [m]."""
    up: Vec3 = (0.0, 0.0, 1.0)
    """The world direction that appears up in the image."""
    width: int = 320
    """Image width [px]."""
    height: int = 240
    """Image height [px]."""
    fov_deg: float = 60.0
    """Vertical field of view [deg]."""
    near: float = 0.1
    """Near clipping distance [m]."""
    far: float = 3.0
    """Far clipping distance [m]; farther surfaces are not seen."""
    rate_hz: float = 15.0
    """Frames per second."""

    def __post_init__(self) -> None:
        """Positive sizes and a sensible frustum."""
        if self.width < 8 or self.height < 8:
            raise ConfigError(
                f"image must be at least 8x8, got {self.width}x{self.height}", "width"
            )
        if not 1.0 < self.fov_deg < 170.0:
            raise ConfigError(f"must be in (1, 170) deg, got {self.fov_deg}", "fov_deg")
        if not 0 < self.near < self.far:
            raise ConfigError(
                f"need 0 < near < far, got near={self.near}, far={self.far}", "near"
            )
        if not self.rate_hz > 0:
            raise ConfigError(f"must be > 0, got {self.rate_hz}", "rate_hz")
        if self.position == self.target:
            raise ConfigError("position and target coincide", "target")


@dataclass(frozen=True, kw_only=True)
class PerceptionSpec:
    """Where the collision world's environment comes from."""

    source: Literal["ground_truth", "depth_camera"] = "ground_truth"
    """``ground_truth``: the declared objects; ``depth_camera``: an occupancy map
    built at run time from the camera's depth images."""
    camera: CameraSpec | None = None
    """The camera (required for ``depth_camera``)."""
    cell_size: float = 0.01
    """Occupancy map resolution [m]."""
    bounds: tuple[Vec3, Vec3] = ((-1.0, -1.0, -0.1), (1.5, 1.0, 1.5))
    """Lower and upper corners of the mapped region [m]."""
    max_range: float = 2.5
    """Depth readings farther than this are ignored [m]."""
    misses_to_clear: int = 2
    """Frames that must see through a cell before it is cleared."""
    robot_margin: float = 0.02
    """Points within the robot's padded shapes plus this margin are filtered [m]."""
    refine_normals: bool = True
    """Re-estimate contact normals from a metaball surface (CAT Sec. IV-B)."""
    metaball_radius_cells: float = 3.0
    """Metaball kernel radius, in cells."""
    metaball_offset_cells: float = 0.5
    """Metaball evaluation point, in cells outside the obstacle witness point."""

    def __post_init__(self) -> None:
        """Camera present for depth_camera; positive sizes; ordered bounds."""
        if self.source == "depth_camera" and self.camera is None:
            raise ConfigError("source 'depth_camera' needs a 'camera:'", "camera")
        if not 0.001 <= self.cell_size <= 0.2:
            raise ConfigError(
                f"must be in [0.001, 0.2] m, got {self.cell_size}", "cell_size"
            )
        lo, hi = self.bounds
        if not all(a < b for a, b in zip(lo, hi, strict=True)):
            raise ConfigError(
                f"lower corner must be below upper, got {lo}, {hi}", "bounds"
            )
        if self.misses_to_clear < 1:
            raise ConfigError(
                f"must be >= 1, got {self.misses_to_clear}", "misses_to_clear"
            )
