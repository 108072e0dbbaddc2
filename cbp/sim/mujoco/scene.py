# SPDX-License-Identifier: Apache-2.0
"""A MuJoCo scene built from the same declarations as PyBullet's.

The robot comes from its URDF (:func:`cbp.sim.mujoco.robot_spec.robot_spec`)
and the objects from the scenario's ``world.objects``. A MuJoCo model is
fixed once compiled, so an object that appears or moves during a run
(:attr:`cbp.scenario.scene.ObjectSpec.dynamic`) is a mocap body from the
start: parked far below the scene until it appears, then placed where its
timeline puts it every step (kinematically: it pushes what it hits, as in
PyBullet). A mesh object that is not convex is one thin convex piece per
triangle (:mod:`cbp.sim.mujoco.meshes`): concave, as PyBullet and the
collision world take it.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings
from cbp.sim.mujoco.meshes import mesh_pieces
from cbp.sim.mujoco.robot_spec import robot_spec

__all__ = ["OBJECT_PREFIX", "PARKED", "MujocoScene"]

#: Body names of the scenario's objects are this prefix and the object's name
#: (a link may have an object's name).
OBJECT_PREFIX = "object/"

#: Where an object waits until it appears [m] (world frame): out of every
#: view and out of reach.
PARKED = np.array([0.0, 0.0, -1000.0])

_SHAPES = {
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
}


class MujocoScene:
    """The robot and the scenario's objects in one MuJoCo model.

    A fixed base is fixed to the world; a planar one is a mocap body that
    :meth:`place_base` puts where the simulation says. Joint limits are as
    stiff as MuJoCo makes them (a time constant of two steps), as PyBullet's
    are hard.

    Args:
        robot: the robot model (its URDF; its locked joints welded).
        objects: the scenario's objects.
        settings: the physics rate and friction.
        folder: where mesh files of objects are resolved from.

    Attributes:
        model: the compiled ``mujoco.MjModel``.
        data: its ``mujoco.MjData``.
        link_bodies: body id per robot link name.
        object_bodies: body id per object name (every declared object, those
            still to appear too).
        dynamic: the objects that appear or move during a run.
    """

    def __init__(
        self,
        robot: RobotModel,
        objects: list[ObjectSpec],
        settings: SimulationSettings,
        folder: Path | None = None,
    ) -> None:
        """Build the spec, add the objects and compile."""
        spec = robot_spec(robot, settings.friction)
        links = [b.name for b in spec.bodies if b.name != "world"]
        spec.option.timestep = 1.0 / settings.rate_hz
        spec.option.gravity = [0.0, 0.0, -9.81]
        for joint in spec.joints:
            # Joint limits as stiff as MuJoCo makes them (a time constant of
            # two steps): hard in PyBullet. At MuJoCo's default (20 ms) JT
            # pressed the Panda 24 mrad past a limit, 0.7 mrad in PyBullet.
            joint.solref_limit = [2.0 * spec.option.timestep, 1.0]
        self.folder = folder or Path.cwd()
        for obj in objects:
            self._add(spec, obj, settings.friction)
        try:
            self.model = spec.compile()
        except ValueError as exc:  # a mesh MuJoCo cannot take (fewer than 4 points)
            message = " ".join(str(exc).split())
            raise ConfigError(f"MuJoCo cannot build the scene: {message}") from None
        self.data = mujoco.MjData(self.model)
        model = self.model

        def body(name: str) -> int:
            return int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name))

        self.link_bodies = {name: body(name) for name in links}
        self._base = self.link_bodies[links[0]]  # the URDF's root link
        self.object_bodies = {o.name: body(OBJECT_PREFIX + o.name) for o in objects}
        self.dynamic = [o for o in objects if o.dynamic]
        self._mocap = {
            o.name: int(model.body_mocapid[self.object_bodies[o.name]])
            for o in self.dynamic
        }
        self.update_objects(0.0)

    def _add(self, spec: mujoco.MjSpec, obj: ObjectSpec, friction: float) -> None:
        """One body for ``obj``: static where declared, or mocap if dynamic."""
        placement = obj.placement_at(0.0)
        body = spec.worldbody.add_body(
            name=OBJECT_PREFIX + obj.name,
            mocap=obj.dynamic,
            pos=placement.translation,
            quat=_wxyz(placement.rotation),
        )
        sliding = [friction * friction, 0.005, 0.0001]
        if obj.shape == "mesh":
            path = (self.folder / obj.file).resolve()
            for k, piece in enumerate(mesh_pieces(path, obj.scale)):
                mesh = spec.add_mesh(
                    name=f"{OBJECT_PREFIX}{obj.name}/{k}",
                    uservert=piece.ravel().tolist(),
                )
                body.add_geom(
                    type=mujoco.mjtGeom.mjGEOM_MESH,
                    meshname=mesh.name,
                    friction=sliding,
                )
            return
        geom = body.add_geom(type=_SHAPES[obj.shape], friction=sliding)
        if obj.shape == "box":
            geom.size = [0.5 * s for s in obj.size]
        elif obj.shape == "sphere":
            geom.size = [obj.size[0], 0.0, 0.0]
        else:
            geom.size = [obj.size[0], 0.5 * obj.size[1], 0.0]

    def place_base(self, x: float, y: float, yaw: float) -> None:
        """Put a moving base (a mocap body) at (x, y) [m] turned by ``yaw`` [rad]."""
        index = self.model.body_mocapid[self._base]
        if index < 0:
            raise ValueError("the robot's base is fixed to the world")
        self.data.mocap_pos[index] = (x, y, 0.0)
        self.data.mocap_quat[index] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))

    def update_objects(self, t: float) -> None:
        """Put each dynamic object where its timeline has it at ``t`` [s].

        One not yet present waits at :data:`PARKED`.
        """
        for obj in self.dynamic:
            index = self._mocap[obj.name]
            if obj.present(t):
                placement = obj.placement_at(t)
                self.data.mocap_pos[index] = placement.translation
                self.data.mocap_quat[index] = _wxyz(placement.rotation)
            else:
                self.data.mocap_pos[index] = PARKED


def _wxyz(rotation: FloatArray) -> FloatArray:
    q = pin.Quaternion(np.asarray(rotation))
    return np.array([q.w, q.x, q.y, q.z])
