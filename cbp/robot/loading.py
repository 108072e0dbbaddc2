# SPDX-License-Identifier: Apache-2.0
"""Loading robots: a URDF's model on its base, and robot.yaml checked against it.

Every problem of a robot folder is reported in one pass, each at its line of
``robot.yaml``: keys that cannot be read, a URDF that does not load or names
missing meshes, and joints or links the URDF does not have.
"""

from __future__ import annotations

import typing
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import pinocchio as pin
import yaml
from yaml.nodes import Node

from cbp.data import is_file
from cbp.errors import ConfigError, close_matches_hint
from cbp.robot.description import BaseType, RobotDescription, find_robot_folder
from cbp.schema import INVALID, Document, value_node
from cbp.urdf_files import missing_meshes

if TYPE_CHECKING:
    from cbp.robot.model import RobotModel

__all__ = ["build_model", "load_robot_folder", "reduced_model"]


def build_model(path: Path, base: BaseType) -> pin.Model:
    """The URDF's model on a fixed, planar or floating base.

    Raises:
        ConfigError: the file is missing or pinocchio cannot read it.
    """
    if not is_file(path):
        raise ConfigError(f"URDF file not found: {path}")
    try:
        if base == "fixed":
            return pin.buildModelFromUrdf(str(path))
        if base == "planar":
            return pin.buildModelFromUrdf(str(path), pin.JointModelPlanar())
        if base == "floating":
            return pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(f"cannot load URDF {path}: {exc}") from exc
    raise ConfigError(f"unknown base '{base}'; expected fixed, planar or floating")


def reduced_model(full: RobotModel, locked_joints: Mapping[str, float]) -> pin.Model:
    """``full``'s model without ``locked_joints``, each held at its given position."""
    ids = [full.joint_id(j) for j in locked_joints]
    q_ref = pin.neutral(full.model)
    for joint, value in locked_joints.items():
        full.set_joint_position(q_ref, joint, value)
    return pin.buildReducedModel(full.model, ids, q_ref)


def load_robot_folder(
    cls: type[RobotModel], name: str, base: BaseType | None, relative_to: Path | None
) -> RobotModel:
    """Robot folder ``name`` as a ``cls`` (see :meth:`RobotModel.load`).

    Raises:
        ScenarioError: every problem of its robot.yaml, each at its line.
    """
    folder = find_robot_folder(name, relative_to)
    doc = Document.from_file(folder / "robot.yaml")
    description = doc.build(RobotDescription, doc.root, "")
    if description is INVALID:
        # The keys that were read are still checked against the URDF, so
        # that one pass reports every problem of the file.
        description = _readable_description(doc)
        if description is None:
            doc.raise_if_problems()
            raise AssertionError("unreachable: the problems were reported")
    base = base or description.base
    path = folder / description.urdf
    try:
        model = build_model(path, base)
    except ConfigError as exc:
        doc.report(value_node(doc.root, "urdf"), "urdf", exc.message)
        doc.raise_if_problems()
        raise  # unreachable: the problem was reported
    for mesh in missing_meshes(path, [folder]):
        doc.report(
            value_node(doc.root, "urdf"),
            "urdf",
            f"{description.urdf}, line {mesh.line}: {mesh.missing}",
        )
    full = cls(model, name=description.name, urdf_path=path)
    _check_names(doc, description, full)
    if description.locked_joints:
        model = reduced_model(full, description.locked_joints)
    robot = cls(
        model,
        name=description.name,
        description=description,
        urdf_path=path,
        base=base,
    )
    robot.folder = folder
    return robot


def _key_nodes(root: Node | None, *keys: str) -> dict[str, Node]:
    """Each key of the mapping at ``keys``, by name, for problems at that line."""
    node = value_node(root, *keys)
    if not isinstance(node, yaml.MappingNode):
        return {}
    return {k.value: k for k, _ in node.value if isinstance(k, yaml.ScalarNode)}


def _readable_description(doc: Document) -> RobotDescription | None:
    """robot.yaml's keys that can be read, with defaults for the others.

    None when a required key (``name``, ``urdf``, ``end_effector``, ``home``)
    cannot be read. The problems of the keys left out are already in ``doc``.
    """
    root = doc.root
    if not isinstance(root, yaml.MappingNode):
        return None
    scratch = Document("", doc.path)  # the problems were reported in doc
    fields = typing.get_type_hints(RobotDescription)
    values: dict[str, object] = {}
    for key_node, node in root.value:
        key = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
        if key in fields:
            value = scratch.build(fields[key], node, key)
            if value is not INVALID:
                values[key] = value
    try:
        return RobotDescription(**values)  # type: ignore[arg-type]
    except (TypeError, ConfigError):
        return None


def _check_names(
    doc: Document, description: RobotDescription, full: RobotModel
) -> None:
    """Every joint and link robot.yaml names is in the URDF (problems at their lines).

    ``full`` is the model before locking joints; a joint robot.yaml locks cannot
    have a home, a velocity or an acceleration limit.
    """
    locked = set(description.locked_joints)
    joints, frames = full.joint_names, full.frame_names
    for key, names in (
        ("locked_joints", description.locked_joints),
        ("home", description.home),
        ("velocity_limits", description.velocity_limits),
        ("acceleration_limits", description.acceleration_limits),
    ):
        nodes = _key_nodes(doc.root, key)
        for joint in names:
            if joint not in joints:
                message = (
                    f"no joint '{joint}' in {full.urdf_name}"
                    + close_matches_hint(joint, joints)
                )
            elif key != "locked_joints" and joint in locked:
                message = (
                    f"joint '{joint}' is locked (locked_joints), so it is not in the "
                    "model: remove it here"
                )
            elif key in ("locked_joints", "home") and (
                problem := full.out_of_range(joint, names[joint])
            ):
                message = problem
            else:
                continue
            doc.report(nodes.get(joint), f"{key}.{joint}", message)
    for key in ("end_effector", "wrist_link"):
        frame = getattr(description, key)
        if frame is not None and frame not in frames:
            doc.report(
                value_node(doc.root, key),
                key,
                f"no frame '{frame}' in {full.urdf_name}"
                + close_matches_hint(frame, frames),
            )
    _check_collision_links(doc, description, full)
    doc.raise_if_problems()


def _check_collision_links(
    doc: Document, description: RobotDescription, full: RobotModel
) -> None:
    """Every link the ``collision:`` section names is in the URDF."""
    collision, frames = description.collision, full.frame_names
    listed = [
        ("ignore_links", i, link) for i, link in enumerate(collision.ignore_links)
    ]
    listed += [
        ("ignore_pairs", i, link)
        for i, pair in enumerate(collision.ignore_pairs)
        for link in pair
    ]
    for key, i, link in listed:
        if link not in frames:
            node = value_node(doc.root, "collision", key)
            item = node.value[i] if isinstance(node, yaml.SequenceNode) else None
            doc.report(
                item or node,
                f"collision.{key}[{i}]",
                f"no link '{link}' in {full.urdf_name}"
                + close_matches_hint(link, frames),
            )
