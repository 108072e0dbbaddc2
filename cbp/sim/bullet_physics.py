# SPDX-License-Identifier: Apache-2.0
"""PyBullet as a simulation's physics (:class:`cbp.sim.physics.Physics`).

The robot in torque mode (its joints' velocity motors off, no joint or link
damping: the torque law has no model of a URDF's ``<dynamics damping>``),
its locked joints (fingers) held by position motors, the scenario's objects
with the scenario's friction. Contact is read from PyBullet's contact points.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings
from cbp.sim.bullet import pb
from cbp.sim.physics import links_beyond
from cbp.sim.scene import PybulletScene

__all__ = ["BulletMobilePhysics", "BulletPhysics"]


class BulletPhysics:
    """The robot and the objects in a PyBullet client (DIRECT, or a window).

    Args:
        robot: the robot model (fixed base, scalar joints).
        objects: the scenario's objects.
        q0: initial configuration.
        settings: the rate and friction.
        folder: where mesh files of objects are resolved from.
        gui: open PyBullet's window.

    Attributes:
        scene: the PyBullet scene (client, body ids).
        client: the PyBullet client id.
        effort: the URDF's effort limits [N m or N] (0: none given).
    """

    def __init__(
        self,
        robot: RobotModel,
        objects: list[ObjectSpec],
        q0: FloatArray,
        settings: SimulationSettings,
        folder: Path | None = None,
        gui: bool = False,
    ) -> None:
        """Load the scene, set the robot at ``q0`` and switch it to torque mode."""
        self.robot = robot
        self.friction = settings.friction
        self.scene = PybulletScene(robot, objects, folder, gui)
        c = self.client = self.scene.client
        pb.setTimeStep(1.0 / settings.rate_hz, physicsClientId=c)
        pb.setGravity(0.0, 0.0, -9.81, physicsClientId=c)
        body = self.scene.robot_id
        model = robot.model
        self._indices = [
            self.scene.joint_index(model.names[j])
            for j in range(1, model.njoints)
            if model.joints[j].nv == 1
        ]
        self.effort = np.array(
            [pb.getJointInfo(body, j, physicsClientId=c)[10] for j in self._indices],
            dtype=float,
        )
        # No joint damping either: the torque law (pinocchio's RNEA) has no model
        # of a URDF's <dynamics damping>, which held an xArm's light wrist
        # 0.67 rad away from its command.
        for link in range(-1, pb.getNumJoints(body, physicsClientId=c)):
            pb.changeDynamics(
                body,
                link,
                linearDamping=0.0,
                angularDamping=0.0,
                jointDamping=0.0,
                lateralFriction=settings.friction,
                physicsClientId=c,
            )
        for obj in self.scene.object_ids.values():
            pb.changeDynamics(
                obj, -1, lateralFriction=settings.friction, physicsClientId=c
            )
        # Locked joints (fingers) are held by PyBullet's position motors; the
        # controlled joints' velocity motors are switched off for torque control.
        self.scene.set_configuration(q0)
        pb.setJointMotorControlArray(
            body,
            self._indices,
            pb.VELOCITY_CONTROL,
            forces=[0.0] * len(self._indices),
            physicsClientId=c,
        )
        locked = robot.description.locked_joints if robot.description else {}
        for name, value in locked.items():
            pb.setJointMotorControl2(
                body,
                self.scene.joint_index(name),
                pb.POSITION_CONTROL,
                targetPosition=value,
                force=100.0,
                physicsClientId=c,
            )
        self._hand_links, self._fixed_links = self._link_sets()

    def apply(self, tau: Sequence[float]) -> None:
        """Set the joints' torques for the next step [N m or N]."""
        pb.setJointMotorControlArray(
            self.scene.robot_id,
            self._indices,
            pb.TORQUE_CONTROL,
            forces=tau,
            physicsClientId=self.client,
        )

    def step(self, t: float) -> None:
        """Add or move the dynamic objects for time ``t`` [s]; step PyBullet."""
        if self.scene.dynamic:
            self.scene.update_objects(t, self.friction)
        pb.stepSimulation(physicsClientId=self.client)

    def state(self) -> tuple[FloatArray, FloatArray]:
        """The joints' positions and velocities."""
        states = pb.getJointStates(
            self.scene.robot_id, self._indices, physicsClientId=self.client
        )
        q = np.array([s[0] for s in states])
        v = np.array([s[1] for s in states])
        return q, v

    def contact(self) -> tuple[float, float, float]:
        """Sum of normal forces, deepest penetration, and the hand's share."""
        robot = self.scene.robot_id
        points = pb.getContactPoints(bodyA=robot, physicsClientId=self.client)
        force = depth = hand = 0.0
        fixed = self._fixed_links
        for p in points:
            if p[2] == robot:  # self-contact is not contact with the scene
                continue
            if p[3] in fixed:  # a fixed base on the floor: no motion of the arm
                continue
            force += p[9]
            depth = max(depth, -p[8])
            if p[3] in self._hand_links:
                hand += p[9]
        return force, depth, hand

    def _link_sets(self) -> tuple[frozenset[int], frozenset[int]]:
        """PyBullet's link indices of the hand, and of the links fixed to the world.

        The base is link -1. The fixed links are
        :meth:`cbp.robot.RobotModel.fixed_links`, by name: the floor they
        stand on is not a contact of the arm.
        """
        c, body = self.client, self.scene.robot_id
        base = pb.getBodyInfo(body, physicsClientId=c)[0].decode()
        index = {base: -1}
        parents: dict[str, str | None] = {base: None}
        names = {-1: base}
        for j in range(pb.getNumJoints(body, physicsClientId=c)):
            info = pb.getJointInfo(body, j, physicsClientId=c)
            names[j] = info[12].decode()
            index[names[j]] = j
        for j in range(pb.getNumJoints(body, physicsClientId=c)):
            parent = pb.getJointInfo(body, j, physicsClientId=c)[16]
            parents[names[j]] = names[parent]
        hand = links_beyond(self.robot, parents)
        fixed = self.robot.fixed_links()
        return (
            frozenset(index[name] for name in hand),
            frozenset(index[name] for name in fixed if name in index),
        )

    def close(self) -> None:
        """Disconnect from PyBullet."""
        self.scene.close()


class BulletMobilePhysics:
    """A robot on a kinematic base in PyBullet, its arm on PyBullet's joint motors.

    The base is placed where it is told each step (its wheels are not
    simulated); the arm's joints track a position reference and a velocity
    through PyBullet's position motors, limited by the URDF's effort.

    Args:
        robot: a model on a planar base.
        objects: the scenario's objects.
        q0: initial configuration (planar layout: x, y, cos yaw, sin yaw, arm).
        settings: the rate.
        folder: where mesh files of objects are resolved from.
        gui: open PyBullet's window.

    Attributes:
        scene: the PyBullet scene (client, body ids).
        client: the PyBullet client id.
    """

    def __init__(
        self,
        robot: RobotModel,
        objects: list[ObjectSpec],
        q0: FloatArray,
        settings: SimulationSettings,
        folder: Path | None = None,
        gui: bool = False,
    ) -> None:
        """Load the scene and set the arm at ``q0``'s joint positions."""
        self.scene = PybulletScene(robot, objects, folder, gui)
        c = self.client = self.scene.client
        pb.setTimeStep(1.0 / settings.rate_hz, physicsClientId=c)
        pb.setGravity(0.0, 0.0, -9.81, physicsClientId=c)
        model = robot.model
        self._indices = [
            self.scene.joint_index(model.names[j])
            for j in range(2, model.njoints)  # joint 1 is the planar base
        ]
        body = self.scene.robot_id
        for k, j in enumerate(self._indices):
            pb.resetJointState(body, j, float(q0[4 + k]), physicsClientId=c)
        self._forces = [
            max(float(pb.getJointInfo(body, j, physicsClientId=c)[10]), 1e-3)
            for j in self._indices
        ]

    def place_base(self, x: float, y: float, yaw: float) -> None:
        """Put the base at (x, y) [m] turned by ``yaw`` [rad]."""
        pb.resetBasePositionAndOrientation(
            self.scene.robot_id,
            [x, y, 0.0],
            pb.getQuaternionFromEuler([0.0, 0.0, yaw]),
            physicsClientId=self.client,
        )

    def drive(self, reference: FloatArray, velocity: FloatArray) -> None:
        """Servo the arm's joints to ``reference`` moving at ``velocity``."""
        pb.setJointMotorControlArray(
            self.scene.robot_id,
            self._indices,
            pb.POSITION_CONTROL,
            targetPositions=reference.tolist(),
            targetVelocities=velocity.tolist(),
            forces=self._forces,
            physicsClientId=self.client,
        )

    def step(self, t: float) -> None:
        """Add or move the dynamic objects for time ``t`` [s]; step PyBullet."""
        if self.scene.dynamic:
            self.scene.update_objects(t)
        pb.stepSimulation(physicsClientId=self.client)

    def arm_positions(self) -> FloatArray:
        """The arm's joint positions."""
        states = pb.getJointStates(
            self.scene.robot_id, self._indices, physicsClientId=self.client
        )
        return np.array([s[0] for s in states])

    def close(self) -> None:
        """Disconnect from PyBullet."""
        self.scene.close()
