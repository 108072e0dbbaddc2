# SPDX-License-Identifier: Apache-2.0
"""A mobile manipulator: a holonomic base and an arm, by velocity.

The base is driven like the youBot's omnidirectional base under its own
velocity controller: each physics step moves the base by the commanded
(v_x, v_y) [m/s, base frame] and yaw rate [rad/s] held over it, along the arc
they trace, and places it there (a kinematic base: its wheels and their slip
are not simulated). The arm's joints follow the
commanded velocities through the engine's joint servos
(:class:`cbp.sim.physics.MobilePhysics`), which track the integrated
position reference and the velocity, limited by the joints' effort. The
configuration is pinocchio's planar one: ``q = (x, y, cos yaw, sin yaw,
arm...)``, ``v = (v_x, v_y, yaw rate, arm...)``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings
from cbp.sim.bullet_access import PybulletAccess
from cbp.sim.physics import MobilePhysics, make_mobile_physics

__all__ = ["MobileSimulation"]


class MobileSimulation(PybulletAccess):
    """The robot on a planar base among the scene's objects, on a physics engine.

    Args:
        robot: a model on a planar base (``base: planar``).
        objects: the scene's objects.
        q0: initial configuration (planar layout).
        settings: physics rate.
        folder: where mesh files of objects are resolved from.
        gui: open the engine's window (PyBullet's).
        simulator: the engine, by name (:data:`cbp.sim.physics.SIMULATORS`).

    Attributes:
        physics: the engine (:class:`cbp.sim.physics.MobilePhysics`).
        t: simulated time [s].
        steps: physics steps taken.
    """

    def __init__(
        self,
        robot: RobotModel,
        objects: list[ObjectSpec],
        q0: FloatArray,
        settings: SimulationSettings | None = None,
        folder: Path | None = None,
        gui: bool = False,
        *,
        simulator: str = "pybullet",
    ) -> None:
        """Load the scene, place the base and the arm, switch on the servos."""
        if robot.base != "planar":
            raise ValueError(
                f"MobileSimulation drives a planar base; '{robot.name}' has "
                f"base '{robot.base}'"
            )
        self.robot = robot
        self.settings = settings or SimulationSettings()
        self.simulator = simulator
        self.dt = 1.0 / self.settings.rate_hz
        q0 = np.asarray(q0, dtype=float)
        self.physics: MobilePhysics = make_mobile_physics(
            simulator, robot, objects, q0, self.settings, folder, gui
        )
        self._base = np.array([q0[0], q0[1], math.atan2(q0[3], q0[2])])
        self._place_base()
        self._reference = np.array(q0[4:], dtype=float)
        self._command = np.zeros(robot.nv)
        self.t = 0.0
        self.steps = 0

    def command(self, velocity: FloatArray) -> None:
        """Set the commanded velocity ``v`` (nv): base (v_x, v_y, yaw rate), arm."""
        v = np.asarray(velocity, dtype=float)
        if v.shape != (self.robot.nv,) or not np.all(np.isfinite(v)):
            raise ValueError(f"expected {self.robot.nv} finite velocities, got {v}")
        self._command = v.copy()

    def run_until(self, t_end: float) -> None:
        """Step the physics (and the base) until ``t_end`` [s]."""
        while self.t + 0.5 * self.dt < t_end:
            vx, vy, wz = self._command[:3]
            # The base moves with a constant twist over the physics step: along
            # the arc it traces (SE(2)'s exponential, as the model's integrate).
            turn = wz * self.dt
            if abs(turn) > 1e-9:
                along, across = math.sin(turn) / turn, (1.0 - math.cos(turn)) / turn
                vx, vy = along * vx - across * vy, across * vx + along * vy
            yaw = self._base[2]
            c, s = math.cos(yaw), math.sin(yaw)
            self._base += self.dt * np.array([c * vx - s * vy, s * vx + c * vy, wz])
            self._place_base()
            # The arm's joint controllers integrate the velocity command into a
            # position reference and track both (as the youBot's joint drives do
            # in velocity mode), so position errors do not accumulate.
            arm = self._command[3:]
            self._reference += self.dt * arm
            self.physics.drive(self._reference, arm)
            self.physics.step(self.t + self.dt)
            self.steps += 1
            self.t = self.steps * self.dt

    @property
    def q(self) -> FloatArray:
        """Measured configuration (planar layout)."""
        x, y, yaw = self._base
        return np.concatenate(
            [[x, y, math.cos(yaw), math.sin(yaw)], self.physics.arm_positions()]
        )

    def _place_base(self) -> None:
        x, y, yaw = self._base
        self.physics.place_base(float(x), float(y), float(yaw))

    def close(self) -> None:
        """Release the engine."""
        self.physics.close()

    def __enter__(self) -> MobileSimulation:
        """Use as a context manager."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Release the engine."""
        self.close()
