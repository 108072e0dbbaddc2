# SPDX-License-Identifier: Apache-2.0
"""``scene.json``: what a page needs to draw a scenario's scene, written and read here.

Every output folder holds one (:func:`write_scene`, for ``cbp view``), and the
live pages draw from the same description (:func:`scene_description`): the
robot's URDF with the joints robot.yaml locks, and the declared objects as
written, with the tracks of those that appear or move.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.scenario.runtime import Scenario
from cbp.schema import to_plain

__all__ = [
    "SCENE_FILE",
    "TRACK_PERIOD",
    "read_scene",
    "scene_description",
    "write_scene",
]

#: What a replay needs to draw the run (:func:`scene_description`).
SCENE_FILE = "scene.json"


#: Objects that appear or move are tracked this often in a scene description [s].
TRACK_PERIOD = 0.05


def scene_description(
    scenario: Scenario, duration: float | None = None
) -> dict[str, Any]:
    """The robot and the objects of ``scenario``, for drawing a replay.

    The URDF (absolute path) with the joints robot.yaml locks, and the declared
    objects as written (shape, size, pose, appearance and motion). Objects that
    appear or move have a ``track`` too: rows of (t, present, x, y, z, qx, qy,
    qz, qw) every :data:`TRACK_PERIOD` over ``duration`` (default the
    scenario's), for a replay to draw them where they were.
    """
    robot = scenario.robot
    description = robot.description
    end = scenario.spec.duration if duration is None else duration
    tracks = {}
    for o in scenario.spec.world.objects:
        if not o.dynamic:
            continue
        rows = []
        for t in np.arange(0.0, end + TRACK_PERIOD, TRACK_PERIOD):
            placement = o.placement_at(float(t))
            q = pin.Quaternion(placement.rotation)
            present = float(o.present(float(t)))
            rows.append([float(t), present, *placement.translation, q.x, q.y, q.z, q.w])
        tracks[o.name] = np.round(np.array(rows), 6).tolist()
    return {
        "tracks": tracks,
        "scenario": scenario.spec.name,
        "urdf": str(robot.urdf_path.resolve()) if robot.urdf_path else None,
        "locked_joints": dict(description.locked_joints) if description else {},
        "objects": [to_plain(o) for o in scenario.spec.world.objects],
        "folder": str(scenario.path.parent.resolve()),
    }


def write_scene(folder: Path, scenario: Scenario, end: float) -> Path:
    """Write ``scenario``'s description, tracked until ``end`` [s], into ``folder``."""
    path = folder / SCENE_FILE
    path.write_text(json.dumps(scene_description(scenario, end)))
    return path


def read_scene(folder: Path) -> dict[str, Any]:
    """The scene description in output folder ``folder``.

    Raises:
        ConfigError: the folder has none (written before scene.json came).
    """
    path = folder / SCENE_FILE
    if not path.is_file():
        raise ConfigError(
            f"{folder} has no {SCENE_FILE} (written by cbp since the viewer "
            "came): run the scenario again"
        )
    description: dict[str, Any] = json.loads(path.read_text())
    return description
