# SPDX-License-Identifier: Apache-2.0
"""Cameras for a MotionBenchMaker problem: its sensor file's, and ours.

:func:`our_cameras` turns ``configs/cat.yaml``'s five cameras to face the
goal: a head camera above and behind the base, one to either side of the
line from the base to the goal, one beyond the goal looking back, and the
wrist camera. :func:`mbm_cameras` places MotionBenchMaker's: every camera
point looking at every look point, with its field of view at 320 x 240
pixels, each camera at a rate that keeps the frames per second of all of
them near those of our five. Both give ``perception.cameras`` entries.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import yaml

from cbp.data import data_dir
from cbp.mbm.files import Family, Primitive
from cbp.robot import FloatArray

__all__ = ["mbm_cameras", "our_cameras"]

CAT_CONFIG = data_dir("scenarios") / "configs" / "cat.yaml"
#: Frames per second of all MotionBenchMaker cameras together (our five
#: cameras give 75).
MBM_FRAMES_PER_SECOND = 75.0
#: Our fixed cameras stay this far from every object [m] (moved toward
#: their target until they are).
CAMERA_CLEARANCE = 0.05


def _fixed(name: str, position: FloatArray, target: FloatArray) -> dict[str, Any]:
    return {
        "name": name,
        "position": [round(float(v), 4) for v in position],
        "target": [round(float(v), 4) for v in target],
    }


def our_cameras(
    goal: FloatArray, clear: Callable[[FloatArray], FloatArray]
) -> list[dict[str, Any]]:
    """``configs/cat.yaml``'s five cameras, turned to face ``goal`` (4, 4).

    ``clear(points)`` gives each point's clearance to the objects [m]; a
    fixed camera nearer than :data:`CAMERA_CLEARANCE` to one is moved toward
    its target, 2 cm at a time, until it is not.
    """
    c = goal[:3, 3]
    reach = max(float(np.hypot(c[0], c[1])), 0.3)
    yaw = math.atan2(c[1], c[0]) if reach > 0.3 else 0.0
    u = np.array([math.cos(yaw), math.sin(yaw), 0.0])  # from the base to the goal
    v = np.array([-u[1], u[0], 0.0])  # its left
    up = np.array([0.0, 0.0, 1.0])
    middle = 0.5 * reach * u + c[2] * up
    placed = [
        ("head", -0.35 * u + max(1.15, c[2] + 0.8) * up, c),
        ("side", middle - 1.1 * v + 0.3 * up, middle),
        ("left", middle + 1.1 * v + 0.3 * up, middle),
        ("front", (reach + 0.3) * u - 0.25 * v + (c[2] + 0.15) * up, middle),
    ]
    cameras = []
    with open(CAT_CONFIG) as f:
        template = {c["name"]: c for c in yaml.safe_load(f)["perception"]["cameras"]}
    for name, position, target in placed:
        p = np.asarray(position, dtype=float)
        step = (target - p) / max(float(np.linalg.norm(target - p)), 1e-9)
        for _ in range(40):
            if float(clear(p[None])[0]) >= CAMERA_CLEARANCE:
                break
            p = p + 0.02 * step
        intrinsics = {
            k: template[name][k] for k in ("width", "height", "fov_deg", "far")
        }
        cameras.append({**_fixed(name, p, target), **intrinsics, "rate_hz": 15.0})
    cameras.append(template["wrist"])
    return cameras


def mbm_cameras(family: Family, objects: Sequence[Primitive]) -> list[dict[str, Any]]:
    """MotionBenchMaker's cameras for the sampled ``objects``.

    Each camera point looks at each look point (a look object's pose times
    its offset); the look object's pose is the sampled one, the camera
    points stay in the base frame, as in MotionBenchMaker's octomap
    generator.
    """
    s = family.sensors
    poses = {o.name: o.pose for o in objects}
    count = len(s.look_objects) * len(s.cam_points)
    rate = round(MBM_FRAMES_PER_SECOND / count, 2)
    cameras = []
    for i, (name, offset) in enumerate(s.look_objects):
        if name not in poses:
            continue  # MotionBenchMaker reports it and goes on
        look = poses[name][:3, :3] @ np.asarray(offset) + poses[name][:3, 3]
        for j, point in enumerate(s.cam_points):
            cameras.append(
                {
                    **_fixed(f"mbm_{i}_{j}", np.asarray(point), look),
                    "width": 320,
                    "height": 240,
                    "fov_deg": round(s.fov_deg, 2),
                    "near": s.near,
                    "far": min(s.far, 2.5),
                    "rate_hz": rate,
                }
            )
    return cameras
