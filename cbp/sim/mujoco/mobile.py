# SPDX-License-Identifier: Apache-2.0
"""MuJoCo under a :class:`~cbp.sim.mobile.MobileSimulation` (``simulator: mujoco``).

The base is a mocap body placed each step (kinematic, as in PyBullet). The
arm's joints are servoed as PyBullet's position motors servo them: each step
the arm is given the torques that bring its joints to their target
velocities by the step's end (on the arm's block of the mass matrix, with
the bias forces), each capped at the URDF's effort; a joint's target is the
commanded velocity plus a tenth of its position error per step,
``v + 0.1 (q_ref - q) / dt`` (the motors' default gains: position 0.1,
velocity 1).

Simpler servos did not do on the youBot's light wrist and small efforts
(1 to 9.5 N m): a velocity actuator capped at the effort, or the same
torques joint by joint on the mass matrix's diagonal, chattered from one cap
to the other, 4 to 18 mrad off the reference where PyBullet's motors keep
0.8 mrad (0.8 mrad with the whole block).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from cbp.errors import ConfigError
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings
from cbp.sim.mujoco.scene import MujocoScene

__all__ = ["POSITION_GAIN", "MujocoMobilePhysics"]

#: The fraction of the position error the servos close per step (PyBullet's
#: position motors' default position gain).
POSITION_GAIN = 0.1


class MujocoMobilePhysics:
    """A robot on a kinematic base in MuJoCo, its arm servoed as PyBullet's.

    Args:
        robot: a model on a planar base.
        objects: the scenario's objects.
        q0: initial configuration (planar layout: x, y, cos yaw, sin yaw, arm).
        settings: the rate and friction.
        folder: where mesh files of objects are resolved from.
        gui: a window: not opened by cbp on MuJoCo (refused).

    Attributes:
        scene: the model, its data and the body ids of links and objects.
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
        """Build the scene; set the arm at ``q0``."""
        if gui:
            raise ConfigError(
                "the MuJoCo simulation opens no window: run it headless", "simulator"
            )
        model = robot.model
        joints = [model.names[j] for j in range(2, model.njoints)]  # 1: the base
        self.scene = MujocoScene(robot, objects, settings, folder)
        m = self.scene.model
        ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joints]
        self._qadr = np.array([m.jnt_qposadr[i] for i in ids])
        self._dadr = np.array([m.jnt_dofadr[i] for i in ids])
        self._mass = np.zeros((m.nv, m.nv))
        effort = np.array([m.jnt_actfrcrange[i][1] for i in ids], dtype=float)
        self._effort = np.maximum(effort, 1e-3)  # PyBullet's motors take the same
        self._dt = m.opt.timestep
        self.scene.data.qpos[self._qadr] = np.asarray(q0, dtype=float)[4:]
        mujoco.mj_forward(m, self.scene.data)

    @property
    def model(self) -> mujoco.MjModel:
        """The compiled model."""
        return self.scene.model

    @property
    def data(self) -> mujoco.MjData:
        """The model's state."""
        return self.scene.data

    def place_base(self, x: float, y: float, yaw: float) -> None:
        """Put the base at (x, y) [m] turned by ``yaw`` [rad]."""
        self.scene.place_base(x, y, yaw)

    def drive(self, reference: FloatArray, velocity: FloatArray) -> None:
        """Servo the arm's joints to ``reference`` moving at ``velocity``."""
        data = self.scene.data
        v = data.qvel[self._dadr]
        target = velocity + POSITION_GAIN * (reference - data.qpos[self._qadr]) / (
            self._dt
        )
        # The mass matrix and the bias forces of the state the step starts from.
        mujoco.mj_fullM(self.scene.model, data, self._mass)
        inertia = self._mass[np.ix_(self._dadr, self._dadr)]
        tau = inertia @ (target - v) / self._dt + data.qfrc_bias[self._dadr]
        data.qfrc_applied[self._dadr] = np.clip(tau, -self._effort, self._effort)

    def step(self, t: float) -> None:
        """Place the dynamic objects for time ``t`` [s]; take one step."""
        if self.scene.dynamic:
            self.scene.update_objects(t)
        mujoco.mj_step(self.scene.model, self.scene.data)

    def arm_positions(self) -> FloatArray:
        """The arm's joint positions."""
        positions: FloatArray = self.scene.data.qpos[self._qadr].copy()
        return positions

    def close(self) -> None:
        """Nothing to release (the model is freed with the object)."""
