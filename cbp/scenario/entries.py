# SPDX-License-Identifier: Apache-2.0
"""A scenario's task and constraint entries bound to plugins, and its start.

Each entry of ``tasks:`` and ``constraints:`` names a plugin type (resolved by
a registry) and its engine keys; its ``params:`` are built into the plugin's
schema and handed to its constructor, whose located problems are recorded in
the document. The robot's initial configuration is read here too.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml

from cbp.errors import ConfigError, suggestion
from cbp.methods import METHODS
from cbp.plugin import Plugin
from cbp.qp import Entry
from cbp.registry import Registry
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.spec import RobotSpec, ScenarioSpec
from cbp.schema import (
    INVALID,
    Document,
    join_path,
    key_nodes,
    mapping_items,
    value_node,
)

__all__ = ["ENTRY_KEYS", "acceleration_rows", "bind_entries", "initial_configuration"]

#: The keys of a task or constraint entry (the plugin's own go under ``params``).
ENTRY_KEYS = ("type", "name", "priority", "weight", "gain", "params")


def bind_entries(
    doc: Document,
    node: yaml.Node,
    section: str,
    registry: Registry[Any],
    robot: RobotModel,
    folder: Path,
) -> list[Entry]:
    """The entries of the list ``node`` (``section``: tasks or constraints).

    Plugin types from ``registry`` (or a dotted path, found beside the
    scenario in ``folder``); an entry with a problem is left out, and its
    problems recorded.
    """
    if not isinstance(node, yaml.SequenceNode):
        doc.report(node, section, "expected a list of entries")
        return []
    entries: list[Entry] = []
    for i, item in enumerate(node.value):
        where = join_path(section, i)
        entry = _bind_entry(doc, item, where, registry, robot, folder)
        if entry is not None:
            entries.append(entry)
    return entries


def _bind_entry(
    doc: Document,
    node: yaml.Node,
    where: str,
    registry: Registry[Any],
    robot: RobotModel,
    folder: Path,
) -> Entry | None:
    items = mapping_items(doc, node, where)
    if items is None:
        return None
    keys = key_nodes(node)
    for key, value in items.items():
        if key not in ENTRY_KEYS:
            doc.report(
                keys.get(key, value),
                join_path(where, key),
                f"unknown key '{key}'{suggestion(key, ENTRY_KEYS)} Entry keys: "
                f"{', '.join(ENTRY_KEYS)} (plugin parameters go under 'params').",
            )
    if "type" not in items:
        doc.report(node, where, f"missing required key 'type' (a {registry.kind} type)")
        return None
    type_name = doc.build(str, items["type"], join_path(where, "type"))
    name = doc.build(str | None, items.get("name"), join_path(where, "name"))
    if type_name is INVALID or name is INVALID:
        return None
    label = f"{where} '{name}'" if name else where
    try:
        cls = registry.get(type_name, search_dirs=[folder])
    except ConfigError as exc:
        doc.report(items["type"], join_path(where, "type"), exc.message)
        return None
    label = f"{label} ({type_name})"
    params = doc.build(cls.Params, items.get("params"), join_path(where, "params"))
    settings = {
        key: doc.build(tp, items[key], join_path(where, key))
        for key, tp in (
            ("priority", Literal["soft", "hard"]),
            ("weight", float | tuple[float, ...]),
            ("gain", float),
        )
        if key in items
    }
    if params is INVALID or INVALID in settings.values():
        return None
    try:
        plugin: Plugin[Any] = cls(params, robot, name or "")
    except ConfigError as exc:
        loc = f"params.{exc.location}" if exc.location else "params"
        key_node = value_node(node, "params", *exc.location.split(".")[:1])
        doc.report(key_node or node, join_path(where, loc), f"{label}: {exc.message}")
        return None
    try:
        return Entry.make(plugin, **settings)
    except ConfigError as exc:
        doc.report(
            items.get(exc.location, node),
            join_path(where, exc.location),
            f"{label}: {exc.message}",
        )
        return None


def initial_configuration(
    doc: Document, spec: RobotSpec, robot: RobotModel, root: yaml.Node
) -> FloatArray:
    """The robot's home posture with ``robot.initial``'s joints set, each checked."""
    q0 = robot.home()
    for joint, value in spec.initial.items():
        try:
            robot.set_joint_position(q0, joint, value)
            problem = robot.out_of_range(joint, value)
        except ConfigError as exc:
            problem = exc.message
        if problem:
            doc.report(
                value_node(root, "robot", "initial", joint),
                f"robot.initial.{joint}",
                problem,
            )
    return q0


def acceleration_rows(
    doc: Document,
    spec: ScenarioSpec,
    entries: list[Entry],
    robot: RobotModel,
    items: Mapping[str, yaml.Node],
) -> tuple[Entry, str] | None:
    """The robot's acceleration rows, when the step guard checks them and none are.

    A method that gives each step the robot's velocity
    (:attr:`cbp.methods.Method.commands_velocity`) has the step guard refuse
    every answer that accelerates past the robot's limits; a scenario of it
    that lists its own constraints without ``joint_acceleration`` (or another
    entry keeping those limits) would have every step refused and the robot
    never move. The rows are added, at the position limits' margin, and the
    loader says so (a log line; the run an event).

    Returns:
        The entry to add and why, located (the plugin's ``added_because``);
        None when none is needed.
    """
    if not METHODS[spec.method.name].commands_velocity:
        return None
    if any(e.plugin.robot_limit == "acceleration" for e in entries):
        return None
    if not np.isfinite(robot.acceleration_limits).any():
        return None
    from cbp.plugins.constraints.joint_acceleration_constraint import (
        JointAccelerationConstraint,
        JointAccelerationParams,
    )

    margin = max(
        (
            float(getattr(e.plugin.params, "margin", 0.0))
            for e in entries
            if e.plugin.robot_limit == "position"
        ),
        default=0.0,
    )
    names = {e.name for e in entries}
    name = "joint_acceleration"
    while name in names:
        name += "_added"
    plugin = JointAccelerationConstraint(
        JointAccelerationParams(margin=margin), robot, name
    )
    node = items.get("constraints")
    where = (
        f"line {node.start_mark.line + 1}: constraints"
        if node is not None and node.start_mark is not None
        else "constraints"
    )
    plugin.added_because = (
        f"{where}: no entry keeps the robot's acceleration limits, which the "
        f"{spec.method.name} executor's step guard checks: '{name}' "
        f"(joint_acceleration, margin {margin:g}) was added from the robot's "
        "limits; list it to choose its settings"
    )
    return Entry.make(plugin), plugin.added_because
