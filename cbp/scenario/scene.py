# SPDX-License-Identifier: Apache-2.0
"""What a scenario declares of its scene: objects, their motion, the physics.

Plain data, read by the simulator (:mod:`cbp.sim`) and the collision world alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError, require, require_between
from cbp.spatial import Pose

__all__ = [
    "MAX_OBJECT_SPEED",
    "ObjectMotion",
    "ObjectSpec",
    "SimulationSettings",
    "SimulatorName",
]

#: The physics engines a scenario can name (``simulator:``;
#: :data:`cbp.sim.physics.SIMULATORS`).
SimulatorName = Literal["pybullet", "mujoco"]

#: Fastest a declared object may move [m/s]. Faster than anything tracked near
#: an arm: ISO 13855 takes 2 m/s for a hand reaching into a machine, and a tool
#: dropped from 3 m lands at under 8 m/s. At the simulator's 1 kHz it moves 2 cm
#: a step, about the arm's thinnest part (a finger): a faster object may pass
#: through the arm between two steps and leave no contact (1e6 m/s did).
MAX_OBJECT_SPEED = 20.0


@dataclass(frozen=True, kw_only=True)
class ObjectMotion:
    """A straight-line motion of an object during a run (``motion:``).

    The object moves at ``velocity`` from ``start`` to ``stop`` and rests
    before and after: a scripted disturbance (an obstacle pushed into the arm,
    a box sliding into its way). The simulator moves it kinematically, whatever
    it hits.
    """

    velocity: tuple[float, float, float]
    """World-frame velocity [m/s]; its speed at most 20 m/s
    (:data:`MAX_OBJECT_SPEED`)."""
    start: float = 0.0
    """When it starts moving [s]."""
    stop: float
    """When it stops [s]."""

    def __post_init__(self) -> None:
        """Times are ordered; the speed finite and at most :data:`MAX_OBJECT_SPEED`."""
        if not 0.0 <= self.start < self.stop < math.inf:
            raise ConfigError(
                f"needs 0 <= start < stop < inf, got start {self.start}, "
                f"stop {self.stop}",
                "stop",
            )
        if not all(math.isfinite(v) for v in self.velocity):
            raise ConfigError(f"must be finite, got {list(self.velocity)}", "velocity")
        speed = math.hypot(*self.velocity)
        if speed > MAX_OBJECT_SPEED:
            raise ConfigError(
                f"{speed:.3g} m/s is faster than any obstacle tracked near an arm "
                f"(at most {MAX_OBJECT_SPEED:g} m/s; a tool dropped from 3 m lands "
                "at 8 m/s); faster, the simulator may move it through the arm "
                "between two steps",
                "velocity",
            )

    def offset(self, t: float) -> np.ndarray:
        """Displacement from the declared pose at time ``t`` [m]."""
        moved = min(max(t - self.start, 0.0), self.stop - self.start)
        return moved * np.asarray(self.velocity, dtype=float)

    def velocity_at(self, t: float) -> np.ndarray:
        """World-frame velocity at time ``t`` [m/s]: zero before and after."""
        moving = self.start <= t < self.stop
        return np.asarray(self.velocity if moving else (0.0, 0.0, 0.0), dtype=float)


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
    appear_at: float = 0.0
    """When the object enters the scene [s]: 0, there from the start; later, it
    appears then (for an obstacle that cameras must discover during a run)."""
    motion: ObjectMotion | None = None
    """A straight-line motion during the run; none: it stays at ``pose``."""
    allow_contact: list[str] = field(default_factory=list)
    """Robot links that may touch this object (wanted contact: a gripper on what
    it grasps or pushes): their pairs with it are left out of the contact
    constraints, step validation and the planners' checks (declared objects)."""

    @property
    def dynamic(self) -> bool:
        """The object appears or moves during the run."""
        return self.appear_at > 0.0 or self.motion is not None

    def present(self, t: float) -> bool:
        """The object is in the scene at time ``t``."""
        return t >= self.appear_at

    def velocity_at(self, t: float) -> np.ndarray:
        """The object's world-frame velocity at time ``t`` [m/s]."""
        if self.motion is None:
            return np.zeros(3)
        return self.motion.velocity_at(t)

    def placement_at(self, t: float) -> pin.SE3:
        """The object's world placement at time ``t``."""
        placement = self.pose.to_se3()
        if self.motion is not None:
            placement.translation = placement.translation + self.motion.offset(t)
        return placement

    def __post_init__(self) -> None:
        """The size matches the shape and is positive; meshes name a file."""
        if not 0.0 <= self.appear_at < math.inf:
            raise ConfigError(
                f"must be >= 0 and finite, got {self.appear_at}", "appear_at"
            )
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
    own_process: bool = False
    """On the wall clock, run the simulated robot in a process of its own, in
    real time (:mod:`cbp.driver.process`): it does not wait for the controller,
    and brakes when commands go stale. The virtual clock steps it in lockstep."""

    def __post_init__(self) -> None:
        """A rate of 100 Hz to 10 kHz, positive gains and recording stride."""
        require_between(self, 100.0, 10_000.0, "Hz", "rate_hz")
        require(self, "> 0", "stiffness", "damping")
        require_between(self, 1, 10_000, "physics steps", "record_every")
        require(self, ">= 0", "friction")
