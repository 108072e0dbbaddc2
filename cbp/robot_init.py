# SPDX-License-Identifier: Apache-2.0
"""Bring your own arm: a ``robot.yaml`` written from a URDF, with its assumptions.

:func:`describe_urdf` reads a URDF (fixed base, revolute and prismatic joints)
and chooses what ``robot.yaml`` needs:

* the end effector: the named frame, else the hand: the link a gripper's
  joints (fingers, knuckles) are attached to, else the last link of the longest
  chain (the link farthest from the root, in joints);
* locked joints: the gripper's, held at the middle of their range (a teleoperated
  arm moves its hand; the fingers are not part of the QP);
* home: the given posture, else the middle of every joint's range;
* velocity limits: the URDF's (``<limit velocity=...>``); a joint without one
  gets :data:`DEFAULT_VELOCITY`;
* acceleration limits: :data:`DEFAULT_ACCELERATION` for every joint (URDF has
  none; set your arm's datasheet values);
* self-collision pairs to skip: the pairs of links that never collide (or always
  do) in sampled configurations (MoveIt's setup-assistant method,
  :func:`~cbp.collision.geometry.find_ignorable_pairs`).

``cbp robot init URDF --out DIR`` copies the URDF and its meshes into DIR
(:mod:`cbp.urdf_files`), writes ``DIR/robot.yaml`` and prints what it assumed,
with a warning for each joint whose range is narrower than twice a shipped
configuration's joint-limit margin. A scenario may also name a
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
from cbp.errors import ConfigError, RobotNotFoundError, ScenarioError
from cbp.files import MAX_YAML_BYTES, check_file
from cbp.hand import find_hand, mimic_joints
from cbp.robot import BaseType, RobotDescription, RobotModel
from cbp.schema import from_plain
from cbp.urdf_files import missing_meshes

if TYPE_CHECKING:
    from cbp.collision.geometry import RobotGeometry

__all__ = [
    "DEFAULT_ACCELERATION",
    "DEFAULT_VELOCITY",
    "RobotSetup",
    "describe_urdf",
    "load_robot",
    "margin_warnings",
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
        warnings: one sentence per thing that will not work as it is.
    """

    document: dict[str, Any]
    assumptions: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def describe_urdf(
    urdf: Path,
    *,
    name: str | None = None,
    end_effector: str | None = None,
    home: dict[str, float] | None = None,
    samples: int = 2000,
    seed: int = 0,
    urdf_entry: str | None = None,
    lock_gripper: bool = True,
) -> RobotSetup:
    """Choose robot.yaml's contents for ``urdf`` (see the module docstring).

    Args:
        urdf: the URDF file.
        name: the robot's name (default: the URDF's ``<robot name>``).
        end_effector: the frame goal tasks move (default: the hand, else the
            last link of the longest chain).
        home: home posture by joint name (default: mid-range).
        samples: configurations sampled for self-collision pairs (0: none).
        seed: seed of the sampling.
        urdf_entry: how robot.yaml names the URDF (default: its path).
        lock_gripper: lock the gripper's joints (found as for the hand).

    Raises:
        ConfigError: the URDF cannot be read, a named frame or joint is not
            in it, or a home position is outside its joint's range.
        ScenarioError: mesh files the URDF names are missing (each at its line).
    """
    check_file(urdf, "URDF", MAX_YAML_BYTES * 8)
    try:
        model = pin.buildModelFromUrdf(str(urdf))
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(f"cannot load URDF {urdf}: {exc}") from None
    missing = missing_meshes(urdf)
    if missing:
        raise ScenarioError(
            str(urdf), [f"line {mesh.line}: {mesh.missing}" for mesh in missing]
        )
    if model.njoints < 2:
        raise ConfigError(f"URDF {urdf} has no movable joint")
    notes: list[str] = []
    hand = find_hand(model)
    locked: dict[str, float] = {}
    if hand.gripper_joints and lock_gripper:
        full = RobotModel(model)
        middle = full.middle()
        locked = {
            j: round(full.joint_position(middle, j), 4) for j in hand.gripper_joints
        }
        for joint, (driver, factor, offset) in mimic_joints(urdf).items():
            if joint in locked and driver in locked:  # where the driver puts it
                locked[joint] = round(factor * locked[driver] + offset, 4)
        notes.append(
            "locked joints (the gripper's, held at the middle of their range; "
            "--control-gripper keeps them in the QP): "
            + ", ".join(f"{j} {v:g}" for j, v in locked.items())
        )
    elif hand.gripper_joints:
        notes.append(f"gripper joints kept in the QP: {', '.join(hand.gripper_joints)}")
    robot = RobotModel.from_urdf(urdf, locked_joints=locked, name=name or model.name)
    if end_effector is None:
        end_effector = hand.frame
        notes.append(f"end effector: {hand.frame}, {hand.reason}")
    else:
        robot.frame_id(end_effector)  # a ConfigError naming the choices
    joints = robot.joint_names
    posture: dict[str, float] = {}
    middle = robot.middle()
    for joint in joints:
        posture[joint] = round(robot.joint_position(middle, joint), 4)
    if home:
        for joint, value in home.items():
            robot.joint_id(joint)
            problem = robot.out_of_range(joint, value)
            if problem:
                raise ConfigError(problem, f"home.{joint}")
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
    }
    if locked:
        document["locked_joints"] = locked
    document["home"] = posture
    document["acceleration_limits"] = dict.fromkeys(joints, DEFAULT_ACCELERATION)
    if velocity:
        document["velocity_limits"] = velocity
    # The collision geometry, loaded once: needed for the self-collision pairs
    # (its errors then stop here), wanted for the depth cameras' note.
    geometry = _geometry(robot, required=samples > 0)
    if samples > 0:
        from cbp.collision.geometry import find_ignorable_pairs

        assert geometry is not None
        pairs = find_ignorable_pairs(geometry, np.random.default_rng(seed), samples)
        document["collision"] = {"ignore_pairs": [list(p) for p in pairs]}
        notes.append(
            f"self-collision: {len(pairs)} link pairs never (or always) collide in "
            f"{samples} random configurations (seed {seed}) and are skipped"
        )
    warnings = margin_warnings(robot)
    if geometry is not None and geometry.shapes:
        measured, note = _visual_note(geometry)
        (notes if measured else warnings).append(note)
    return RobotSetup(document, notes, warnings)


def margin_warnings(robot: RobotModel) -> list[str]:
    """Joints too short for the joint-limit margin of a shipped configuration.

    One sentence per (configuration, joint) whose range is narrower than twice
    the margin: such a scenario fails to load with that robot.
    """
    from cbp.data import config_path, shipped_configs
    from cbp.schema import Document

    warnings = []
    ranges = {}
    for joint in robot.joint_names:
        rows = robot.joint_q_slice(joint)
        lo, hi = robot.lower_limits[rows], robot.upper_limits[rows]
        if lo.size == 1 and np.isfinite(lo[0]) and np.isfinite(hi[0]):
            ranges[joint] = (float(lo[0]), float(hi[0]))
    for config in shipped_configs():
        path = config_path(config)
        assert path is not None
        doc = Document.from_file(path)
        doc.resolve_includes()
        plain = doc.plain(doc.root) if doc.root is not None else {}
        for entry in plain.get("constraints") or []:
            if entry.get("type") != "joint_limits":
                continue
            params = entry.get("params") or {}
            margin = float(params.get("margin", 0.0))
            joints = params.get("joints") or list(ranges)
            short = [
                f"{joint} [{ranges[joint][0]:g}, {ranges[joint][1]:g}]"
                for joint in joints
                if joint in ranges and ranges[joint][1] - ranges[joint][0] < 2 * margin
            ]
            if short:
                warnings.append(
                    f"'include: {config}' keeps joints {margin:g} from their limits, "
                    f"more than half the range of {', '.join(short)}: lock them "
                    "(locked_joints) or set a smaller margin in your scenario"
                )
    return warnings


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
        locked_joints=description.locked_joints,
        name=description.name,
        description=description,
    )
    robot.folder = path.parent
    return robot


def write_robot_yaml(setup: RobotSetup, out: Path) -> Path:
    """Write ``out/robot.yaml`` with the assumptions and warnings as a header."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / "robot.yaml"
    header = "".join(f"# {line}\n" for line in setup.assumptions) + "".join(
        f"# warning: {line}\n" for line in setup.warnings
    )
    path.write_text(
        "# Written by cbp robot init; assumptions:\n"
        + header
        + yaml.safe_dump(setup.document, sort_keys=False)
    )
    return path


def relative_urdf(urdf: Path, out: Path) -> str:
    """How robot.yaml in ``out`` names ``urdf``."""
    return os.path.relpath(urdf.resolve(), out.resolve())


def _geometry(robot: RobotModel, required: bool) -> RobotGeometry | None:
    """The URDF's collision geometry; None when it cannot be read and not required."""
    from cbp.collision.geometry import RobotGeometry

    try:
        return RobotGeometry(robot)
    except ConfigError:
        if required:
            raise
        return None  # said where the geometry is loaded for a run


def _visual_note(geometry: RobotGeometry) -> tuple[bool, str]:
    """How far the links look larger than their collision shapes, for depth cameras.

    Returns:
        Whether it was measured (False: the visual geometry could not be read
        and every link takes the fallback), and the sentence to print.
    """
    from cbp.collision.geometry import UNREAD_VISUAL_EXCESS

    excess = geometry.visual_excess
    if np.all(excess == UNREAD_VISUAL_EXCESS):
        return False, (
            "depth cameras: the visual meshes could not be read (see the message "
            f"above); the self-filter takes every link to look "
            f"{1000 * UNREAD_VISUAL_EXCESS:.0f} mm larger than its collision shapes"
        )
    worst = int(np.argmax(excess))
    return True, (
        "depth cameras: the visual meshes reach up to "
        f"{1000 * excess[worst]:.1f} mm past the collision shapes "
        f"({geometry.shapes[worst].link}); the self-filter grows each link by "
        "its own, so readings of the arm are not taken for obstacles"
    )
