# SPDX-License-Identifier: Apache-2.0
"""A mobile manipulator in PyBullet: a holonomic base and an arm, by velocity.

The base is driven like the youBot's omnidirectional base under its own
velocity controller: each physics step moves the base by the commanded
(v_x, v_y) [m/s, base frame] and yaw rate [rad/s] held over it, along the arc
they trace, and places it there (a kinematic base: its wheels and their slip
are not simulated). The arm's joints follow the
commanded velocities through PyBullet's joint motors, which track the
integrated position reference and the velocity, limited by the joints'
effort. The configuration is pinocchio's planar one:
``q = (x, y, cos yaw, sin yaw, arm...)``, ``v = (v_x, v_y, yaw rate, arm...)``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cbp.errors import ConfigError
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings
from cbp.sim.bullet import pb
from cbp.sim.scene import PybulletScene

__all__ = ["MobileSimulation"]


class MobileSimulation:
    """The robot on a planar base among the scene's objects.

    Args:
        robot: a model on a planar base (``base: planar``).
        objects: the scene's objects.
        q0: initial configuration (planar layout).
        settings: physics rate.
        folder: where mesh files of objects are resolved from.
        gui: open PyBullet's window.
        simulator: the physics engine: PyBullet only (``pybullet``).
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
        """Load the scene, place the base and the arm, switch on velocity motors."""
        if simulator != "pybullet":
            raise ConfigError(
                f"a robot on a planar base runs on PyBullet only, not on "
                f"'{simulator}' (docs/simulators.md says why)",
                "simulator",
            )
        if robot.base != "planar":
            raise ValueError(
                f"MobileSimulation drives a planar base; '{robot.name}' has "
                f"base '{robot.base}'"
            )
        self.robot = robot
        self.settings = settings or SimulationSettings()
        self.scene = PybulletScene(robot, objects, folder, gui)
        self.client = self.scene.client
        self.dt = 1.0 / self.settings.rate_hz
        pb.setTimeStep(self.dt, physicsClientId=self.client)
        pb.setGravity(0.0, 0.0, -9.81, physicsClientId=self.client)
        model = robot.model
        self._indices = [
            self.scene.joint_index(model.names[j])
            for j in range(2, model.njoints)  # joint 1 is the planar base
        ]
        body = self.scene.robot_id
        self._effort = [
            float(pb.getJointInfo(body, j, physicsClientId=self.client)[10])
            for j in self._indices
        ]
        q0 = np.asarray(q0, dtype=float)
        self._base = np.array([q0[0], q0[1], math.atan2(q0[3], q0[2])])
        for k, j in enumerate(self._indices):
            pb.resetJointState(body, j, float(q0[4 + k]), physicsClientId=self.client)
        self._place_base()
        self._reference = np.array(q0[4:], dtype=float)
        self._forces = [max(e, 1e-3) for e in self._effort]
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
            pb.setJointMotorControlArray(
                self.scene.robot_id,
                self._indices,
                pb.POSITION_CONTROL,
                targetPositions=self._reference.tolist(),
                targetVelocities=arm.tolist(),
                forces=self._forces,
                physicsClientId=self.client,
            )
            if self.scene.dynamic:
                self.scene.update_objects(self.t + self.dt)
            pb.stepSimulation(physicsClientId=self.client)
            self.steps += 1
            self.t = self.steps * self.dt

    @property
    def q(self) -> FloatArray:
        """Measured configuration (planar layout)."""
        states = pb.getJointStates(
            self.scene.robot_id, self._indices, physicsClientId=self.client
        )
        x, y, yaw = self._base
        return np.concatenate(
            [[x, y, math.cos(yaw), math.sin(yaw)], [s[0] for s in states]]
        )

    def _place_base(self) -> None:
        x, y, yaw = self._base
        pb.resetBasePositionAndOrientation(
            self.scene.robot_id,
            [float(x), float(y), 0.0],
            pb.getQuaternionFromEuler([0.0, 0.0, float(yaw)]),
            physicsClientId=self.client,
        )

    def close(self) -> None:
        """Disconnect from PyBullet."""
        self.scene.close()

    def __enter__(self) -> MobileSimulation:
        """Use as a context manager."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Disconnect."""
        self.close()
