# SPDX-License-Identifier: Apache-2.0
"""A robot folder's ``robot.yaml`` (its schema), and where robot folders are found."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from cbp.data import data_dir, is_file
from cbp.errors import ConfigError, RobotNotFoundError, close_matches

__all__ = [
    "ROBOTS_DIR",
    "Approximation",
    "BaseType",
    "CollisionDescription",
    "RobotDescription",
    "find_robot_folder",
]

BaseType = Literal["fixed", "planar", "floating"]

#: How mesh collision elements are turned into convex shapes.
Approximation = Literal["hull", "capsule"]

#: Where robot description folders are looked up, after ``CBP_ROBOT_PATH``:
#: the robots that ship with cbp (:func:`cbp.data.data_dir`).
ROBOTS_DIR = data_dir("robots")


@dataclass(frozen=True, kw_only=True)
class CollisionDescription:
    """The ``collision:`` section of ``robot.yaml``: how the links are checked."""

    padding: float = 0.01
    """Distance added around every link for collision checks [m]."""
    ignore_pairs: list[tuple[str, str]] = field(default_factory=list)
    """Link pairs never checked against each other (beyond adjacent links), e.g.
    pairs that cannot collide; ``cbp robot-pairs NAME`` suggests them by sampling."""
    ignore_links: list[str] = field(default_factory=list)
    """Links left out of every collision check (e.g. fingers meant to touch)."""
    approximation: Approximation = "hull"
    """Mesh elements as their convex ``hull``, or the ``capsule`` around it."""

    def __post_init__(self) -> None:
        """Non-negative padding."""
        if not self.padding >= 0:
            raise ConfigError(f"must be >= 0, got {self.padding}", "padding")


@dataclass(frozen=True, kw_only=True)
class RobotDescription:
    """The schema of a robot folder's ``robot.yaml``."""

    name: str
    """Folder name, also the robot's name in scenarios."""
    urdf: str
    """URDF file, relative to the folder."""
    end_effector: str
    """Frame the default goal task controls."""
    home: dict[str, float]
    """Home posture, by joint name [rad or m]; joints left out take their neutral."""
    base: BaseType = "fixed"
    """The base the robot is built for: ``fixed`` (an arm on a table),
    ``planar`` (an omnidirectional base) or ``floating``."""
    wrist_link: str | None = None
    """First link of the hand: contact forces on it and the links beyond it are
    reported as the wrist force (a wrist force sensor's reading)."""
    locked_joints: dict[str, float] = field(default_factory=dict)
    """Joints removed from the model and held at these positions [rad or m]."""
    velocity_limits: dict[str, float] = field(default_factory=dict)
    """Overrides of the URDF velocity limits, by joint name [rad/s or m/s]."""
    acceleration_limits: dict[str, float] = field(default_factory=dict)
    """Acceleration limits by joint name [rad/s^2 or m/s^2]; default 10 for all."""
    collision: CollisionDescription = field(default_factory=CollisionDescription)
    """Collision settings of the robot's links."""


def find_robot_folder(name: str, relative_to: Path | None = None) -> Path:
    """Return the folder of robot ``name``: a path, or a name under the robot path.

    A path is taken relative to ``relative_to`` (a scenario's folder) when
    given, else to the current folder. The search path is ``CBP_ROBOT_PATH``
    (os.pathsep-separated) then the robots that ship with cbp.

    Raises:
        RobotNotFoundError: saying where it looked, with the nearest robot
            folders' names (beside the scenario, in the current folder, on the
            search path).
    """
    direct = ([relative_to / name] if relative_to is not None else []) + [Path(name)]
    for folder in direct:
        if is_file(folder / "robot.yaml"):
            return folder
    roots = [
        Path(p) for p in os.environ.get("CBP_ROBOT_PATH", "").split(os.pathsep) if p
    ]
    roots.append(ROBOTS_DIR)
    for root in roots:
        if is_file(root / name / "robot.yaml"):
            return root / name
    raise _not_found(name, direct, roots)


def _not_found(name: str, direct: list[Path], roots: list[Path]) -> RobotNotFoundError:
    """The error for robot ``name``: where it looked and the nearest folders' names.

    ``direct``: the paths ``name`` was taken as; ``roots``: the search path.
    """
    # Robot folders beside the one named (written as the scenario would name
    # them), then those on the search path (by name).
    parent = Path(name).parent
    local = sorted(
        {
            str(parent / p.parent.name) if str(parent) != "." else p.parent.name
            for folder in direct
            if folder.parent.is_dir()
            for p in folder.parent.glob("*/robot.yaml")
        }
    )
    available = sorted(
        {
            p.parent.name
            for root in roots
            if root.is_dir()
            for p in root.glob("*/robot.yaml")
        }
    )
    hint = close_matches(name, [*local, *available], n=1)
    did_you_mean = f" Did you mean '{hint[0]}'?" if hint else ""
    places: dict[Path, str] = {}
    for folder, label in zip(
        direct,
        ["beside the scenario", "the current folder"][-len(direct) :],
        strict=True,
    ):
        places.setdefault(folder.parent.resolve(), label)
    for root in roots:
        places.setdefault(
            root, "shipped robots" if root == ROBOTS_DIR else "CBP_ROBOT_PATH"
        )
    looked = ", ".join(f"{place} ({label})" for place, label in places.items())
    listing = ", ".join(available) or "none"
    return RobotNotFoundError(
        f"no robot '{name}': no folder '{Path(name).name}' with a robot.yaml in "
        f"{looked}.{did_you_mean} Robots on the search path: {listing}."
    )
