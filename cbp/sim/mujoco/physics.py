# SPDX-License-Identifier: Apache-2.0
"""MuJoCo as a simulation's physics (:class:`cbp.sim.physics.Physics`).

Torques reach the joints as applied generalized forces (``qfrc_applied``:
no actuator dynamics, no gear), already clipped to the URDF's effort limits
by the controller. Contact is measured as PyBullet's is: the normal force of
every contact between a robot link and a scene object
(``mujoco.mj_contactForce``), self-contact and the fixed base's links left
out; the deepest penetration; the hand's share.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from cbp.errors import ConfigError
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings
from cbp.sim.mujoco.scene import MujocoScene
from cbp.sim.physics import links_beyond

__all__ = ["MujocoPhysics"]

# What a geom belongs to, for contact (MujocoPhysics._kind).
_SCENE, _ARM, _HAND, _FIXED = 0, 1, 2, 3


class MujocoPhysics:
    """The robot and the objects in one MuJoCo model, torque-driven.

    Args:
        robot: the robot model (fixed base, scalar joints).
        objects: the scenario's objects.
        q0: initial configuration.
        settings: the rate and friction.
        folder: where mesh files of objects are resolved from.
        gui: a window: MuJoCo's viewer is not opened by cbp (refused).

    Attributes:
        scene: the model, its data and the body ids of links and objects.
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
        """Build the scene and put the robot at ``q0``, at rest."""
        if gui:
            raise ConfigError(
                "the MuJoCo simulation opens no window: run it headless", "simulator"
            )
        self.robot = robot
        self.scene = MujocoScene(robot, objects, settings, folder)
        model = self.model
        pin_model = robot.model
        joints = [
            pin_model.names[j]
            for j in range(1, pin_model.njoints)
            if pin_model.joints[j].nv == 1
        ]
        ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joints]
        missing = [n for n, i in zip(joints, ids, strict=True) if i < 0]
        if missing:
            raise ValueError(f"joints {missing} are not in the MuJoCo model")
        self._qadr = np.array([model.jnt_qposadr[i] for i in ids])
        self._dadr = np.array([model.jnt_dofadr[i] for i in ids])
        self.effort = np.array([model.jnt_actfrcrange[i][1] for i in ids], dtype=float)
        self._kind = self._geom_kinds()
        self.data.qpos[self._qadr] = np.asarray(q0, dtype=float)
        mujoco.mj_forward(model, self.data)
        self._force = np.zeros(6)

    @property
    def model(self) -> mujoco.MjModel:
        """The compiled model."""
        return self.scene.model

    @property
    def data(self) -> mujoco.MjData:
        """The model's state."""
        return self.scene.data

    def apply(self, tau: Sequence[float]) -> None:
        """Set the joints' generalized forces for the next step [N m or N]."""
        self.data.qfrc_applied[self._dadr] = tau

    def step(self, t: float) -> None:
        """Place the dynamic objects for time ``t`` [s]; take one step."""
        if self.scene.dynamic:
            self.scene.update_objects(t)
        mujoco.mj_step(self.model, self.data)

    def state(self) -> tuple[FloatArray, FloatArray]:
        """The joints' positions and velocities."""
        return self.data.qpos[self._qadr].copy(), self.data.qvel[self._dadr].copy()

    def contact(self) -> tuple[float, float, float]:
        """Sum of normal forces, deepest penetration, and the hand's share."""
        data = self.data
        n = data.ncon
        if n == 0:
            return 0.0, 0.0, 0.0
        kinds = self._kind[data.contact.geom[:n]]
        robot = np.where(kinds[:, 0] == _SCENE, kinds[:, 1], kinds[:, 0])
        other = np.where(kinds[:, 0] == _SCENE, kinds[:, 0], kinds[:, 1])
        # Robot against scene only: not self-contact, not the fixed base.
        counted = np.flatnonzero(
            (other == _SCENE) & ((robot == _ARM) | (robot == _HAND))
        )
        force = depth = hand = 0.0
        out = self._force
        for i in counted:
            mujoco.mj_contactForce(self.model, data, int(i), out)
            force += out[0]
            depth = max(depth, -float(data.contact.dist[i]))
            if robot[i] == _HAND:
                hand += out[0]
        return float(force), depth, float(hand)

    def _geom_kinds(self) -> np.ndarray:
        """Each geom's owner: scene, arm, hand, or a link fixed to the world."""
        model, scene = self.model, self.scene
        parents = {
            name: (
                model.body(int(model.body_parentid[body])).name
                if model.body_parentid[body] != 0
                else None
            )
            for name, body in scene.link_bodies.items()
        }
        hand = links_beyond(self.robot, parents)
        fixed = self.robot.fixed_links()
        by_body = np.full(model.nbody, _SCENE)
        for name, body in scene.link_bodies.items():
            by_body[body] = _FIXED if name in fixed else _HAND if name in hand else _ARM
        kinds: np.ndarray = by_body[model.geom_bodyid]
        return kinds

    def close(self) -> None:
        """Nothing to release (the model is freed with the object)."""
