# SPDX-License-Identifier: Apache-2.0
"""Drawing in the browser with viser, shared by every page (replay, teleoperation).

The declared objects of a scene description (:mod:`cbp.scene_file`), a
gripper, rotations in viser's quaternion order, and a robot's configuration
as the joint values of its URDF. viser is imported by the callers, which
pass their server.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cbp.robot import FloatArray
from cbp.spatial import Pose

__all__ = [
    "RobotPose",
    "add_gripper",
    "add_robot",
    "draw_objects",
    "joint_values",
    "wxyz",
]

#: The colour of declared objects (RGB 0-255).
OBJECT_COLOUR = (170, 170, 170)


def draw_objects(server: Any, description: dict[str, Any]) -> dict[str, Any]:
    """Draw the declared objects of a scene description.

    ``description`` is :func:`cbp.scene_file.scene_description`'s.
    """
    scene = server.scene
    handles: dict[str, Any] = {}
    for obj in description["objects"]:
        pose = Pose(**obj["pose"]).to_se3()
        quat = wxyz(pose.rotation)
        name = f"/objects/{obj['name']}"
        size = obj.get("size") or []
        colour = OBJECT_COLOUR
        if obj["shape"] == "box":
            handles[obj["name"]] = scene.add_box(
                name,
                color=colour,
                dimensions=tuple(size),
                wxyz=quat,
                position=tuple(pose.translation),
            )
        elif obj["shape"] == "sphere":
            handles[obj["name"]] = scene.add_icosphere(
                name, radius=size[0], color=colour, position=tuple(pose.translation)
            )
        elif obj["shape"] == "cylinder":
            handles[obj["name"]] = scene.add_cylinder(
                name,
                radius=size[0],
                height=size[1],
                color=colour,
                wxyz=quat,
                position=tuple(pose.translation),
            )
        elif obj["shape"] == "mesh":
            import trimesh

            mesh = trimesh.load(
                str(Path(description["folder"]) / obj["file"]), force="mesh"
            )
            mesh.apply_scale(obj.get("scale", [1.0, 1.0, 1.0]))
            handles[obj["name"]] = scene.add_mesh_trimesh(
                name, mesh, wxyz=quat, position=tuple(pose.translation)
            )
    return handles


def add_robot(
    server: Any, urdf: str | Path, name: str, colour: tuple[int, int, int]
) -> Any:
    """A robot drawn from its URDF's collision meshes, in one colour.

    Args:
        server: the viser server.
        urdf: the robot's URDF file.
        name: the scene node the robot hangs under (``/robot``).
        colour: RGB 0-255.

    Returns:
        viser's ``ViserUrdf`` of it (its ``update_cfg`` poses it), which can
        also send single joints (:class:`RobotPose`).
    """
    return _posable_urdf()(
        server,
        Path(urdf),
        root_node_name=name,
        load_meshes=False,
        load_collision_meshes=True,
        collision_mesh_color_override=(
            colour[0] / 255,
            colour[1] / 255,
            colour[2] / 255,
        ),
    )


def wxyz(rotation: FloatArray) -> tuple[float, float, float, float]:
    """The quaternion (w, x, y, z), viser's order, of a rotation matrix."""
    import pinocchio as pin

    q = pin.Quaternion(rotation)
    return (float(q.w), float(q.x), float(q.y), float(q.z))


def joint_values(
    joints: Sequence[str],
    values: Mapping[str, float],
    locked: Mapping[str, float],
) -> FloatArray:
    """The values of a URDF's actuated ``joints``, in their order.

    From the robot's coordinates by name (``values``), else the joints
    robot.yaml locks (``locked``), else 0.
    """
    return np.array([values.get(j, locked.get(j, 0.0)) for j in joints], dtype=float)


def add_gripper(
    server: Any, name: str, colour: tuple[int, int, int] = (200, 60, 60)
) -> Any:
    """A two-finger gripper of boxes under frame ``name`` (opening along y, z out).

    Hidden until shown; ``colour`` is RGB 0-255.
    """
    frame = server.scene.add_frame(name, show_axes=False, visible=False)
    server.scene.add_box(
        f"{name}/palm", colour, (0.02, 0.16, 0.03), position=(0.0, 0.0, -0.04)
    )
    for side in (-1, 1):
        server.scene.add_box(
            f"{name}/finger{side}",
            colour,
            (0.015, 0.015, 0.05),
            position=(0.0, 0.06 * side, 0.0),
        )
    return frame


@functools.cache
def _posable_urdf() -> type[Any]:
    """The class of :func:`add_robot`'s robots (viser is imported late)."""
    from viser.extras import ViserUrdf

    class PosableUrdf(ViserUrdf):
        """A ``ViserUrdf`` that sends the frames of chosen joints only."""

        def joint_frames(self) -> list[tuple[Any, Any]]:
            """Each joint of the URDF (yourdfpy's) with its frame, in order.

            viser 1.1.1 keeps them in step (collision meshes only: one frame
            per joint).
            """
            return list(zip(self._joint_map_values, self._joint_frames, strict=True))

        @property
        def scale(self) -> float:
            """The robot's drawn scale."""
            return float(self._scale)

    return PosableUrdf


class RobotPose:
    """Poses a robot drawn by :func:`add_robot`, sending only the joints that moved.

    viser's ``ViserUrdf.update_cfg`` computes the whole URDF's kinematics and
    sends a rotation and a translation for every joint's frame at each call
    (24 messages for a Panda, about 2 ms of the interpreter); an arm in
    motion changes a few joints' angles. Here each joint's frame is sent
    only when the value it depends on (its own, or the one it mimics) moved
    by more than ``tolerance`` from the value drawn, and only what the joint
    changes: a revolute joint's rotation, a prismatic joint's translation.

    Args:
        robot: the robot of :func:`add_robot`.
        tolerance: a joint that moved less than this is not sent [rad, m].
    """

    def __init__(self, robot: Any, tolerance: float) -> None:
        """Read the URDF's joints; nothing drawn yet (the first pose sends all)."""
        names = list(robot.get_actuated_joint_names())
        self.robot = robot
        self.tolerance = tolerance
        self._scale = robot.scale
        #: Per joint frame: the frame, the joint, the index of the actuated
        #: value it follows (None: fixed), the mimic's multiplier and offset.
        self._frames: list[tuple[Any, Any, int | None, float, float]] = []
        for joint, frame in robot.joint_frames():
            if joint.type == "fixed":
                self._frames.append((frame, joint, None, 1.0, 0.0))
            elif joint.mimic is not None and joint.mimic.joint in names:
                self._frames.append(
                    (
                        frame,
                        joint,
                        names.index(joint.mimic.joint),
                        float(joint.mimic.multiplier),
                        float(joint.mimic.offset),
                    )
                )
            elif joint.name in names:
                self._frames.append((frame, joint, names.index(joint.name), 1.0, 0.0))
            else:  # mimics a joint that is not actuated: fixed at its offset
                self._frames.append((frame, joint, None, 1.0, 0.0))
        #: The values drawn (None: nothing yet).
        self.drawn: FloatArray | None = None

    def moved(self, values: FloatArray) -> bool:
        """Whether ``values`` would send anything (a joint moved, or the first pose)."""
        drawn = self.drawn
        return (
            drawn is None
            or drawn.shape != values.shape
            or bool(np.any(np.abs(values - drawn) > self.tolerance))
        )

    def pose(self, values: FloatArray) -> bool:
        """Draw the robot at the URDF's actuated joint ``values``; whether any sent."""
        values = np.asarray(values, dtype=float)
        drawn = self.drawn
        if drawn is None or drawn.shape != values.shape:
            self.robot.update_cfg(values)  # every frame, translations included
            self.drawn = values.copy()
            return True
        changed = np.abs(values - drawn) > self.tolerance
        if not changed.any():
            return False
        for frame, joint, index, multiplier, offset in self._frames:
            if index is None or not changed[index]:
                continue
            q = float(values[index]) * multiplier + offset
            origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin)
            axis = np.asarray(joint.axis, dtype=float)
            if joint.type == "prismatic":
                frame.position = tuple(
                    (origin[:3, 3] + origin[:3, :3] @ (q * axis)) * self._scale
                )
            else:  # revolute, continuous
                import pinocchio as pin

                unit = axis / np.linalg.norm(axis)
                frame.wxyz = wxyz(origin[:3, :3] @ pin.exp3(q * unit))
        drawn[changed] = values[changed]
        return True
