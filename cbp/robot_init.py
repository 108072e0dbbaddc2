# SPDX-License-Identifier: Apache-2.0
"""Bring your own arm: a ``robot.yaml`` written from a URDF, with its assumptions.

:func:`describe_urdf` reads a URDF (fixed base, revolute and prismatic joints)
and chooses what ``robot.yaml`` needs:

* the end effector: the named frame, else the last link of the longest chain
  (the link farthest from the root, in joints);
* home: the given posture, else the middle of every joint's range;
* velocity limits: the URDF's (``<limit velocity=...>``); a joint without one
  gets :data:`DEFAULT_VELOCITY`;
* acceleration limits: :data:`DEFAULT_ACCELERATION` for every joint (URDF has
  none; set your arm's datasheet values);
* self-collision pairs to skip: the pairs of links that never collide (or always
  do) in sampled configurations (MoveIt's setup-assistant method,
  :func:`~cbp.collision.geometry.find_ignorable_pairs`).

``cbp robot init URDF --out DIR`` writes ``DIR/robot.yaml`` (the URDF named by
a path relative to DIR) and prints what it assumed. A scenario may also name a
URDF directly (``robot: {name: path/to/arm.urdf}``): the same choices are made
in memory, without the pair sampling (adjacent links are skipped only).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin
import yaml

from cbp.data import is_file
from cbp.errors import ConfigError, RobotNotFoundError
from cbp.files import MAX_YAML_BYTES, check_file
from cbp.robot import BaseType, RobotDescription, RobotModel
from cbp.schema import from_plain

if TYPE_CHECKING:
    from cbp.collision.geometry import RobotGeometry

__all__ = [
    "DEFAULT_ACCELERATION",
    "DEFAULT_VELOCITY",
    "RobotSetup",
    "describe_urdf",
    "load_robot",
    "write_robot_yaml",
]

#: Acceleration limit given to every joint [rad/s^2 or m/s^2].
DEFAULT_ACCELERATION = 10.0
#: Velocity limit of a joint whose URDF gives none [rad/s or m/s].
DEFAULT_VELOCITY = 1.0


@dataclass
class RobotSetup:
    """What ``robot.yaml`` will say, and what was assumed to say it.

    Attributes:
        document: the robot.yaml contents.
        assumptions: one sentence per choice made for the user.
    """

    document: dict[str, Any]
    assumptions: list[str] = field(default_factory=list)


def describe_urdf(
    urdf: Path,
    *,
    name: str | None = None,
    end_effector: str | None = None,
    home: dict[str, float] | None = None,
    samples: int = 2000,
    seed: int = 0,
    urdf_entry: str | None = None,
) -> RobotSetup:
    """Choose robot.yaml's contents for ``urdf`` (see the module docstring).

    Args:
        urdf: the URDF file.
        name: the robot's name (default: the URDF's ``<robot name>``).
        end_effector: the frame goal tasks move (default: the last link of the
            longest chain).
        home: home posture by joint name (default: mid-range).
        samples: configurations sampled for self-collision pairs (0: none).
        seed: seed of the sampling.
        urdf_entry: how robot.yaml names the URDF (default: its path).

    Raises:
        ConfigError: the URDF cannot be read, or a named frame or joint is not
            in it.
    """
    check_file(urdf, "URDF", MAX_YAML_BYTES * 8)
    try:
        model = pin.buildModelFromUrdf(str(urdf))
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(f"cannot load URDF {urdf}: {exc}") from None
    if model.njoints < 2:
        raise ConfigError(f"URDF {urdf} has no movable joint")
    robot = RobotModel(model, name=name or model.name)
    notes: list[str] = []
    if end_effector is None:
        end_effector = _last_link(model)
        notes.append(
            f"end effector: {end_effector}, the last link of the longest chain "
            "(--end-effector to choose another)"
        )
    else:
        robot.frame_id(end_effector)  # a ConfigError naming the choices
    joints = robot.joint_names
    posture: dict[str, float] = {}
    middle = robot.middle()
    for joint in joints:
        posture[joint] = round(float(middle[robot.joint_q_slice(joint)][0]), 4)
    if home:
        for joint, value in home.items():
            robot.joint_id(joint)
            posture[joint] = float(value)
    else:
        notes.append("home: the middle of every joint's range")
    velocity = {}
    for joint in joints:
        v = float(robot.velocity_limits[robot.joint_v_slice(joint)][0])
        if not np.isfinite(v):
            velocity[joint] = DEFAULT_VELOCITY
            notes.append(
                f"{joint}: the URDF gives no velocity limit; {DEFAULT_VELOCITY} assumed"
            )
    notes.append(
        f"acceleration limits: {DEFAULT_ACCELERATION} for every joint (the URDF has "
        "none; put your arm's datasheet values in robot.yaml)"
    )
    document: dict[str, Any] = {
        "name": robot.name,
        "urdf": urdf_entry or str(urdf),
        "end_effector": end_effector,
        "home": posture,
        "acceleration_limits": dict.fromkeys(joints, DEFAULT_ACCELERATION),
    }
    if velocity:
        document["velocity_limits"] = velocity
    # The collision geometry, loaded once: needed for the self-collision pairs
    # (its errors then stop here), wanted for the depth cameras' note.
    geometry = _geometry(urdf, robot.name, required=samples > 0)
    if samples > 0:
        from cbp.collision.geometry import find_ignorable_pairs

        assert geometry is not None
        pairs = find_ignorable_pairs(geometry, np.random.default_rng(seed), samples)
        document["collision"] = {"ignore_pairs": [list(p) for p in pairs]}
        notes.append(
            f"self-collision: {len(pairs)} link pairs never (or always) collide in "
            f"{samples} random configurations (seed {seed}) and are skipped"
        )
    if geometry is not None and geometry.shapes:
        notes.append(_visual_note(geometry))
    return RobotSetup(document, notes)


def load_robot(
    name: str, base: BaseType | None = None, relative_to: Path | None = None
) -> RobotModel:
    """The robot a scenario names: a robot folder, or a URDF file directly.

    A URDF (``name`` ending in ``.urdf``, relative to ``relative_to`` first)
    gets robot.yaml's choices made with their defaults (no pair sampling).

    Raises:
        ConfigError: no such robot or URDF, or one that cannot be read.
    """
    if not name.endswith(".urdf"):
        return RobotModel.load(name, base=base, relative_to=relative_to)
    candidates = ([relative_to / name] if relative_to is not None else []) + [
        Path(name)
    ]
    path = next((p for p in candidates if is_file(p)), None)
    if path is None:
        raise RobotNotFoundError(f"URDF file not found: {name}")
    setup = describe_urdf(path, samples=0)
    description = from_plain(RobotDescription, setup.document, str(path))
    robot = RobotModel.from_urdf(
        path,
        base=base or description.base,
        name=description.name,
        description=description,
    )
    robot.folder = path.parent
    return robot


def write_robot_yaml(setup: RobotSetup, out: Path) -> Path:
    """Write ``out/robot.yaml`` with the assumptions as a header comment."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / "robot.yaml"
    header = "".join(f"# {line}\n" for line in setup.assumptions)
    path.write_text(
        "# Written by cbp robot init; assumptions:\n"
        + header
        + yaml.safe_dump(setup.document, sort_keys=False)
    )
    return path


def relative_urdf(urdf: Path, out: Path) -> str:
    """How robot.yaml in ``out`` names ``urdf``."""
    return os.path.relpath(urdf.resolve(), out.resolve())


def _last_link(model: pin.Model) -> str:
    """The body frame of the deepest joint (most joints from the root)."""
    depth = [0] * model.njoints
    for j in range(1, model.njoints):
        depth[j] = depth[model.parents[j]] + 1
    deepest = max(range(1, model.njoints), key=lambda j: (depth[j], j))
    # The last body frame attached to that joint (links fixed to it included).
    bodies = [
        f.name
        for f in model.frames
        if f.parentJoint == deepest and f.type == pin.FrameType.BODY
    ]
    return str(bodies[-1])


def _geometry(urdf: Path, name: str, required: bool) -> RobotGeometry | None:
    """The URDF's collision geometry; None when it cannot be read and not required."""
    from cbp.collision.geometry import RobotGeometry

    try:
        return RobotGeometry(RobotModel.from_urdf(urdf, name=name))
    except ConfigError:
        if required:
            raise
        return None  # said where the geometry is loaded for a run


def _visual_note(geometry: RobotGeometry) -> str:
    """How far the links look larger than their collision shapes, for depth cameras."""
    excess = geometry.visual_excess
    worst = int(np.argmax(excess))
    return (
        "depth cameras: the visual meshes reach up to "
        f"{1000 * excess[worst]:.1f} mm past the collision shapes "
        f"({geometry.shapes[worst].link}); the self-filter grows each link by "
        "its own, so readings of the arm are not taken for obstacles"
    )
