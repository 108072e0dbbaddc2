# SPDX-License-Identifier: Apache-2.0
"""A PyBullet scene built from the same declarations as the collision world.

The robot comes from its folder's URDF and the objects from the scenario's
``world.objects``: one declaration, two consumers (the simulator and
:meth:`cbp.scenario.Scenario.collision_world`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Protocol, TypeVar

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings
from cbp.sim.bullet import pb
from cbp.urdf_files import missing_meshes

if TYPE_CHECKING:
    from cbp.scenario.runtime import Scenario

__all__ = ["PybulletScene", "SimulationKind", "simulate"]

S = TypeVar("S", covariant=True)


class SimulationKind(Protocol[S]):
    """A simulation class: built from a scenario's robot, objects and settings."""

    def __call__(
        self,
        robot: RobotModel,
        objects: list[ObjectSpec],
        q0: FloatArray,
        settings: SimulationSettings | None = None,
        folder: Path | None = None,
        gui: bool = False,
        *,
        simulator: str = "pybullet",
    ) -> S:
        """The simulation, on the physics engine named ``simulator``."""


def _unloadable(robot: RobotModel, urdf: Path) -> ConfigError:
    """The error for a URDF PyBullet refuses: its missing meshes, else its log."""
    try:
        reasons = [
            f"line {mesh.line}: {mesh.missing}"
            for mesh in missing_meshes(urdf, [robot.folder] if robot.folder else [])
        ]
    except ConfigError as exc:
        reasons = [exc.message]
    because = "; ".join(reasons) or "its reason is the line PyBullet printed above"
    return ConfigError(
        f"PyBullet cannot load robot '{robot.name}' ({because})", str(urdf)
    )


def simulate(kind: SimulationKind[S], scenario: Scenario, gui: bool = False) -> S:
    """A simulation of ``scenario``: its robot at its start, its objects.

    Args:
        kind: the simulation class (:class:`~cbp.sim.simulation.Simulation`,
            :class:`~cbp.sim.mobile.MobileSimulation`).
        scenario: the loaded scenario (its ``simulation:`` settings, its
            ``simulator:``, its folder for object meshes).
        gui: open a window instead of running headless.
    """
    spec = scenario.spec
    return kind(
        scenario.robot,
        spec.world.objects,
        scenario.q0,
        spec.simulation,
        scenario.path.parent,
        gui,
        simulator=spec.simulator,
    )


class PybulletScene:
    """A PyBullet client (DIRECT by default) holding the robot and the objects.

    Args:
        robot: the robot model (its URDF is loaded with a fixed base).
        objects: the scenario's objects.
        folder: where mesh files of objects are resolved from.
        gui: open a window instead of running headless.

    Attributes:
        client: the PyBullet client id.
        robot_id: the robot's body id.
        object_ids: body id per object name.
    """

    def __init__(
        self,
        robot: RobotModel,
        objects: list[ObjectSpec],
        folder: Path | None = None,
        gui: bool = False,
    ) -> None:
        """Connect and load everything."""
        if robot.urdf_path is None:
            raise ValueError(f"robot '{robot.name}' has no URDF")
        self.robot = robot
        self.client = pb.connect(pb.GUI if gui else pb.DIRECT)
        try:
            self.robot_id = pb.loadURDF(
                str(robot.urdf_path),
                useFixedBase=True,
                flags=pb.URDF_USE_SELF_COLLISION_EXCLUDE_ALL_PARENTS
                | pb.URDF_USE_INERTIA_FROM_FILE,
                physicsClientId=self.client,
            )
        except pb.error:
            pb.disconnect(physicsClientId=self.client)
            raise _unloadable(robot, robot.urdf_path) from None
        self._joint_index: dict[str, int] = {}
        for j in range(pb.getNumJoints(self.robot_id, physicsClientId=self.client)):
            info = pb.getJointInfo(self.robot_id, j, physicsClientId=self.client)
            self._joint_index[info[1].decode()] = j
        if robot.description is not None:
            for joint, value in robot.description.locked_joints.items():
                pb.resetJointState(
                    self.robot_id,
                    self._joint_index[joint],
                    value,
                    physicsClientId=self.client,
                )
        self.object_ids: dict[str, int] = {}
        self.folder = folder or Path.cwd()
        self.dynamic = [obj for obj in objects if obj.dynamic]
        """The objects that appear or move during a run (:meth:`update_objects`)."""
        for obj in objects:
            if obj.present(0.0):
                self.add_object(obj, obj.placement_at(0.0))

    def joint_index(self, name: str) -> int:
        """PyBullet index of the joint called ``name``."""
        try:
            return self._joint_index[name]
        except KeyError:
            raise ValueError(f"no joint '{name}' in the simulated robot") from None

    def add_object(self, obj: ObjectSpec, placement: pin.SE3) -> int:
        """Create a static body for ``obj`` at ``placement``; returns its id.

        Mesh files are resolved from :attr:`folder`.
        """
        c = self.client
        if obj.shape == "box":
            half = [0.5 * s for s in obj.size]
            col = pb.createCollisionShape(
                pb.GEOM_BOX, halfExtents=half, physicsClientId=c
            )
            vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=c)
        elif obj.shape == "sphere":
            col = pb.createCollisionShape(
                pb.GEOM_SPHERE, radius=obj.size[0], physicsClientId=c
            )
            vis = pb.createVisualShape(
                pb.GEOM_SPHERE, radius=obj.size[0], physicsClientId=c
            )
        elif obj.shape == "cylinder":
            r, length = obj.size
            col = pb.createCollisionShape(
                pb.GEOM_CYLINDER, radius=r, height=length, physicsClientId=c
            )
            vis = pb.createVisualShape(
                pb.GEOM_CYLINDER, radius=r, length=length, physicsClientId=c
            )
        else:
            path = str(self.folder / obj.file)
            col = pb.createCollisionShape(
                pb.GEOM_MESH,
                fileName=path,
                meshScale=list(obj.scale),
                flags=pb.GEOM_FORCE_CONCAVE_TRIMESH,
                physicsClientId=c,
            )
            vis = pb.createVisualShape(
                pb.GEOM_MESH,
                fileName=path,
                meshScale=list(obj.scale),
                physicsClientId=c,
            )
        quat = _xyzw(placement.rotation)
        body = pb.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=col,
            baseVisualShapeIndex=vis,
            basePosition=placement.translation.tolist(),
            baseOrientation=quat,
            physicsClientId=c,
        )
        self.object_ids[obj.name] = body
        return int(body)

    def update_objects(self, t: float, friction: float | None = None) -> None:
        """Add the objects due by ``t`` (:attr:`dynamic`); move the moving ones.

        Each is where its timeline puts it at ``t`` (``appear_at``, ``motion``);
        a body added is given ``friction`` (lateral), if set.
        """
        for obj in self.dynamic:
            if not obj.present(t):
                continue
            if obj.name not in self.object_ids:
                body = self.add_object(obj, obj.placement_at(t))
                if friction is not None:
                    pb.changeDynamics(
                        body, -1, lateralFriction=friction, physicsClientId=self.client
                    )
            elif obj.motion is not None:
                self.move_object(obj.name, obj.placement_at(t))

    def move_object(self, name: str, placement: pin.SE3) -> None:
        """Put an object at ``placement`` (kinematically: it pushes what it hits)."""
        pb.resetBasePositionAndOrientation(
            self.object_ids[name],
            placement.translation.tolist(),
            _xyzw(placement.rotation),
            physicsClientId=self.client,
        )

    def remove_object(self, name: str) -> None:
        """Remove an object from the simulation (it stays in the declarations)."""
        pb.removeBody(self.object_ids.pop(name), physicsClientId=self.client)

    def set_configuration(self, q: FloatArray) -> None:
        """Teleport the robot's joints to ``q`` (fixed-base models)."""
        model = self.robot.model
        for j in range(1, model.njoints):
            joint = model.joints[j]
            if joint.nq == 1:
                name = model.names[j]
                pb.resetJointState(
                    self.robot_id,
                    self._joint_index[name],
                    float(q[joint.idx_q]),
                    physicsClientId=self.client,
                )

    def close(self) -> None:
        """Disconnect the client."""
        if pb.isConnected(self.client):
            pb.disconnect(self.client)

    def __enter__(self) -> PybulletScene:
        """Use as a context manager."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Disconnect."""
        self.close()


def _xyzw(rotation: FloatArray) -> list[float]:
    q = pin.Quaternion(np.asarray(rotation))
    return [float(q.x), float(q.y), float(q.z), float(q.w)]
