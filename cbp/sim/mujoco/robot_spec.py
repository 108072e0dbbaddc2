# SPDX-License-Identifier: Apache-2.0
"""A robot's MuJoCo model from its URDF, as PyBullet loads it for a simulation.

MuJoCo compiles URDF; :func:`robot_spec` adds what the URDF cannot say and
makes the model match PyBullet's (:class:`cbp.sim.scene.PybulletScene`):

* static links are kept as bodies (``fusestatic`` off): every link name has a
  body, for contact by link and for cameras mounted on a link;
* the locked joints (fingers) are removed, their links welded at the locked
  value: the controlled joints are the model's (pinocchio's reduced model
  keeps the locked links' inertia the same way);
* no joint damping, armature or friction loss (the torque law has no model of
  them; PyBullet's are set to zero too);
* an inertia no body can have (A + B < C) balanced by MuJoCo, where
  PyBullet zeroes it (pybullet_data's xArm6);
* self-contact between a link and any of its ancestors is excluded
  (PyBullet's ``URDF_USE_SELF_COLLISION_EXCLUDE_ALL_PARENTS``);
* mesh names resolved as the rest of cbp resolves them (``package://``).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from cbp.errors import ConfigError
from cbp.robot import FloatArray, RobotModel
from cbp.urdf_files import resolve_mesh

__all__ = ["robot_spec"]

#: Mesh formats MuJoCo reads.
MESH_FORMATS = (".stl", ".obj", ".msh")


def robot_spec(robot: RobotModel, friction: float) -> mujoco.MjSpec:
    """The robot's URDF as a MuJoCo spec (see the module).

    A fixed base is fixed to the world; another (planar) is a mocap body,
    placed by the simulation.

    Args:
        robot: the robot (its URDF and locked joints).
        friction: each geom's sliding friction coefficient, as PyBullet's
            ``lateralFriction``: the robot's geoms get ``friction**2``
            (MuJoCo combines two geoms' coefficients by their maximum,
            PyBullet by their product).

    Raises:
        ConfigError: MuJoCo cannot read the URDF or one of its meshes.
    """
    urdf = robot.urdf_path
    if urdf is None:
        raise ConfigError(f"robot '{robot.name}' has no URDF", "robot")
    try:
        spec = mujoco.MjSpec.from_file(str(urdf))
    except ValueError as exc:
        raise ConfigError(f"MuJoCo cannot read robot '{robot.name}': {exc}") from None
    spec.compiler.fusestatic = False
    spec.compiler.discardvisual = True
    # An inertia that no body can have (the xArm's link2: A + B < C) is made
    # one by MuJoCo (its nearest with A + B = C); PyBullet zeroes it.
    spec.compiler.balanceinertia = True
    _resolve_meshes(spec, robot, urdf)
    locked = robot.description.locked_joints if robot.description else {}
    _lock(spec, locked)
    for joint in spec.joints:
        joint.damping = np.zeros_like(joint.damping)
        joint.armature = 0.0
        joint.frictionloss = 0.0
    for geom in spec.geoms:
        geom.friction = [friction * friction, *list(geom.friction)[1:]]
    _exclude_ancestors(spec)
    if robot.base != "fixed":
        # A base that moves is placed each step (kinematic), as in PyBullet.
        spec.worldbody.first_body().mocap = True
    return spec


def _resolve_meshes(spec: mujoco.MjSpec, robot: RobotModel, urdf: Path) -> None:
    """Every mesh file by its absolute path; a format MuJoCo cannot read refused."""
    folders = [robot.folder] if robot.folder else []
    for mesh in spec.meshes:
        found = resolve_mesh(mesh.file, urdf.parent, folders)
        if found is None:
            raise ConfigError(
                f"MuJoCo cannot load robot '{robot.name}': no file for mesh "
                f"'{mesh.file}'",
                str(urdf),
            )
        path = found[0].resolve()
        if path.suffix.lower() not in MESH_FORMATS:
            raise ConfigError(
                f"MuJoCo cannot load robot '{robot.name}': mesh '{mesh.file}' is "
                f"{path.suffix} (MuJoCo reads {', '.join(MESH_FORMATS)})",
                str(urdf),
            )
        mesh.file = str(path)


def _lock(spec: mujoco.MjSpec, locked: dict[str, float]) -> None:
    """Remove the locked joints, their links placed at the locked values.

    A joint's mimics (URDF ``<mimic>``, equality constraints) go with it.
    """
    for equality in list(spec.equalities):
        if equality.name1 in locked or equality.name2 in locked:
            spec.delete(equality)
    for name, value in locked.items():
        joint = spec.joint(name)
        if joint is None:
            raise ConfigError(f"no joint '{name}' in the URDF", "locked_joints")
        body = joint.parent
        axis = np.asarray(joint.axis, dtype=float)
        axis /= np.linalg.norm(axis)
        quat = np.asarray(body.quat, dtype=float)
        if joint.type == mujoco.mjtJoint.mjJNT_SLIDE:
            body.pos = np.asarray(body.pos) + _rotate(quat, value * axis)
        elif joint.type == mujoco.mjtJoint.mjJNT_HINGE:
            # About the joint's axis through its anchor (body frame).
            turn = np.empty(4)
            mujoco.mju_axisAngle2Quat(turn, axis, value)
            anchor = np.asarray(joint.pos, dtype=float)
            moved = anchor - _rotate(turn, anchor)
            body.pos = np.asarray(body.pos) + _rotate(quat, moved)
            out = np.empty(4)
            mujoco.mju_mulQuat(out, quat, turn)
            body.quat = out
        else:
            raise ConfigError(f"joint '{name}' is not a scalar joint", "locked_joints")
        spec.delete(joint)


def _rotate(quat: FloatArray, vector: FloatArray) -> FloatArray:
    out = np.empty(3)
    mujoco.mju_rotVecQuat(out, np.asarray(vector, dtype=float), quat)
    return out


def _exclude_ancestors(spec: mujoco.MjSpec) -> None:
    """No contact between a link and any link above it."""
    for body in spec.bodies:
        if body.name == "world":
            continue
        parent = body.parent
        while parent is not None and parent.name != "world":
            spec.add_exclude(bodyname1=parent.name, bodyname2=body.name)
            parent = parent.parent
