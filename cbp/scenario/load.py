# SPDX-License-Identifier: Apache-2.0
"""Scenario files: strict YAML loading into the schema, then binding to plugins.

A scenario names the robot, the world, the goal input, the method (executor) and
its settings, and the lists of task and constraint entries. Every entry has the
engine keys ``type``, ``name``, ``priority``, ``weight`` and ``gain``; what the
plugin itself needs goes under ``params``. All problems of a file are reported
together, each with the file, line, path in the document, what was expected and
the nearest valid choice (:class:`~cbp.errors.ScenarioError`).

:func:`load_scenario` reads the file and runs the rest in order: the entries
are bound to plugins (:mod:`.entries`), and the scenario is checked against
its robot (:mod:`.checks`); the warnings are logged here.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from cbp.errors import CbpError, ConfigError, ScenarioError
from cbp.plugin import UsesCollisionWorld
from cbp.qp import Entry
from cbp.registry import Registry
from cbp.robot import RobotModel
from cbp.robot_init import load_robot
from cbp.scenario.checks import (
    check_allowed_contact,
    check_cameras,
    check_goal,
    check_initial_contact,
    check_inputs,
    check_meshes,
    goal_reach_warnings,
    object_speed_warnings,
)
from cbp.scenario.entries import (
    acceleration_rows,
    bind_entries,
    initial_configuration,
)
from cbp.scenario.runtime import Scenario
from cbp.scenario.spec import RobotSpec, ScenarioSpec
from cbp.schema import INVALID, Document, mapping_items, value_node

__all__ = ["load_scenario"]

log = logging.getLogger(__name__)


def load_scenario(
    path: str | Path,
    *,
    tasks: Registry[Any] | None = None,
    constraints: Registry[Any] | None = None,
    overrides: Mapping[str, str] | None = None,
) -> Scenario:
    """Read, check and bind a scenario file.

    Args:
        path: the YAML file.
        overrides: values that replace the file's, by dotted path
            (``{"perception.source": "depth_camera"}``; values are YAML).
        tasks: task registry (default: the in-tree ``cbp.plugins.tasks.TASKS``).
        constraints: constraint registry (default:
            ``cbp.plugins.constraints.CONSTRAINTS``).

    Raises:
        ScenarioError: listing every problem in the file.
    """
    from cbp.plugins.constraints import CONSTRAINTS
    from cbp.plugins.tasks import TASKS

    tasks = TASKS if tasks is None else tasks
    constraints = CONSTRAINTS if constraints is None else constraints
    path = Path(path)
    doc = Document.from_file(path)
    doc.resolve_includes()
    for dotted, text in (overrides or {}).items():
        doc.override(dotted, text)
    root = doc.root
    spec = doc.build(ScenarioSpec, root, "")
    if root is None:
        doc.raise_if_problems()
        raise AssertionError("unreachable: an empty document records a problem")
    # Entries are bound even when another section is wrong, so that one pass
    # reports every problem of the file.
    robot_spec = spec.robot if spec is not INVALID else _robot_spec_quietly(doc, root)
    robot: RobotModel | None = None
    if robot_spec is not INVALID and robot_spec is not None:
        try:
            robot = load_robot(
                robot_spec.name, base=robot_spec.base, relative_to=path.parent
            )
        except ScenarioError as exc:  # robot.yaml's problems, at its lines
            doc.problems += [
                f"{exc.path}, {p}" if p.startswith("line ") else f"{exc.path}: {p}"
                for p in exc.problems
            ]
        except CbpError as exc:
            doc.report(value_node(root, "robot", "name"), "robot.name", str(exc))
    entries: list[Entry] = []
    q0 = np.zeros(0)
    if robot is not None:
        items = mapping_items(doc, root, "") or {}
        for section, registry in (("tasks", tasks), ("constraints", constraints)):
            node = items.get(section)
            if node is not None:
                entries += bind_entries(
                    doc, node, section, registry, robot, path.parent
                )
        q0 = initial_configuration(doc, robot_spec, robot, root)
        if spec is not INVALID:
            added = acceleration_rows(doc, spec, entries, robot, items)
            if added is not None:
                entries.append(added[0])
                log.warning("%s, %s", doc.path, added[1])
            check_meshes(doc, spec, root, path.parent)
            check_allowed_contact(doc, spec, robot, root)
            check_goal(doc, spec, entries, root, path.parent)
            check_inputs(doc, spec, entries, root)
            check_cameras(doc, spec, robot, root)
        names = [e.name for e in entries]
        for name in sorted({n for n in names if names.count(n) > 1}):
            doc.report(
                None,
                "tasks/constraints",
                f"entry name '{name}' is used twice; give each entry its own 'name'",
            )
    doc.raise_if_problems()
    assert robot is not None
    scenario = Scenario(
        path=path, spec=spec, robot=robot, entries=tuple(entries), q0=q0
    )
    if scenario.needs_collision_world:
        try:
            world = scenario.new_world()
        except ConfigError as exc:
            where = f" ({exc.location})" if exc.location else ""
            raise ScenarioError(
                str(path), [f"collision world{where}: {exc.message}"]
            ) from exc
        for entry in entries:
            if isinstance(entry.plugin, UsesCollisionWorld):
                entry.plugin.attach_world(world)
        scenario = dataclasses.replace(scenario, world=world)
    check_initial_contact(doc, scenario, root)
    doc.raise_if_problems()
    for warning in goal_reach_warnings(doc, scenario, root) + object_speed_warnings(
        doc, scenario, root
    ):
        log.warning("%s, %s", doc.path, warning)
    return scenario


def _robot_spec_quietly(doc: Document, root: yaml.Node) -> Any:
    """Build the robot section, whose problems were already reported; else INVALID."""
    node = value_node(root, "robot")
    saved = len(doc.problems)
    value = doc.build(RobotSpec, node, "robot") if node is not None else INVALID
    del doc.problems[saved:]
    return value
