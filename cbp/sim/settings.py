# SPDX-License-Identifier: Apache-2.0
"""What the simulator is built from: scene objects and physics settings."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from cbp.errors import ConfigError, require
from cbp.spatial import Pose

__all__ = ["ObjectSpec", "SimulationSettings"]


@dataclass(frozen=True, kw_only=True)
class ObjectSpec:
    """One object of the world: a primitive or a mesh at a pose.

    The collision world and the simulator both build their objects from this
    declaration.
    """

    name: str
    """Object name."""
    shape: Literal["box", "sphere", "cylinder", "mesh"]
    """Primitive type, or ``mesh`` (a file)."""
    size: tuple[float, ...] = ()
    """box: (x, y, z) edges; sphere: (radius,); cylinder: (radius, length) [m]."""
    file: str = ""
    """Mesh file (mesh only), relative to the scenario file."""
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """Mesh scale per axis (mesh only)."""
    pose: Pose
    """Pose of the object's frame (a primitive's centre), world frame."""

    def __post_init__(self) -> None:
        """The size matches the shape and is positive; meshes name a file."""
        if self.shape == "mesh":
            if not self.file:
                raise ConfigError("a mesh needs 'file:'", "file")
            if self.size:
                raise ConfigError("a mesh takes 'scale', not 'size'", "size")
            return
        expected = {"box": 3, "sphere": 1, "cylinder": 2}[self.shape]
        if len(self.size) != expected:
            raise ConfigError(
                f"a {self.shape} takes {expected} size values, got {len(self.size)}",
                "size",
            )
        if not all(s > 0 for s in self.size):
            raise ConfigError(f"sizes must be > 0, got {list(self.size)}", "size")


@dataclass(frozen=True, kw_only=True)
class SimulationSettings:
    """The ``simulation:`` section of a scenario."""

    rate_hz: float = 1000.0
    """Physics and low-level control rate [Hz]."""
    stiffness: float = 900.0
    """Joint impedance: Kp of the computed-torque law [1/s^2]."""
    damping: float = 60.0
    """Joint impedance: Kd of the computed-torque law [1/s]."""
    record_every: int = 5
    """Record one trace sample every this many physics steps (contact force
    peaks are measured at every step regardless)."""
    friction: float = 0.5
    """Lateral friction of the robot's links and the scene's objects."""

    def __post_init__(self) -> None:
        """Positive rate, gains and recording stride."""
        require(self, "> 0", "rate_hz", "stiffness", "damping")
        require(self, ">= 1", "record_every")
        require(self, ">= 0", "friction")
