# SPDX-License-Identifier: Apache-2.0
"""Drawing in the browser with viser, shared by every page (replay, teleoperation).

The declared objects of a scene description (:mod:`cbp.scene_file`), a
gripper, rotations in viser's quaternion order, and a robot's configuration
as the joint values of its URDF. viser is imported by the callers, which
pass their server.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cbp.robot import FloatArray
from cbp.spatial import Pose

__all__ = ["add_gripper", "add_robot", "draw_objects", "joint_values", "wxyz"]

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
        viser's ``ViserUrdf`` of it (its ``update_cfg`` poses it).
    """
    from viser.extras import ViserUrdf

    return ViserUrdf(
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
