# SPDX-License-Identifier: Apache-2.0
"""Scenario files: strict YAML loading into the schema, then binding to plugins.

A scenario names the robot, the world, the goal input, the method (executor) and
its settings, and the lists of task and constraint entries. Every entry has the
engine keys ``type``, ``name``, ``priority``, ``weight`` and ``gain``; what the
plugin itself needs goes under ``params``. All problems of a file are reported
together, each with the file, line, path in the document, what was expected and
the nearest valid choice (:class:`~cbp.errors.ScenarioError`).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import coal
import numpy as np
import yaml

from cbp.collision.environment import signed_distance
from cbp.collision.geometry import RobotGeometry
from cbp.errors import CbpError, ConfigError, ScenarioError, suggestion
from cbp.expressions import check_over, compile_time_function, run_times
from cbp.files import load_mesh
from cbp.goals import GoalStream
from cbp.methods import METHODS
from cbp.perception.frame import camera_parent
from cbp.plugin import Plugin, TakesInput, UsesCollisionWorld
from cbp.qp import Entry
from cbp.registry import Registry
from cbp.robot import FloatArray, RobotModel
from cbp.robot_init import load_robot
from cbp.scenario.runtime import Scenario, goal_receivers
from cbp.scenario.spec import RobotSpec, ScenarioSpec
from cbp.schema import (
    INVALID,
    Document,
    join_path,
    key_nodes,
    mapping_items,
    value_node,
)
from cbp.state import RobotState

__all__ = ["load_scenario"]

log = logging.getLogger(__name__)

_ENTRY_KEYS = ("type", "name", "priority", "weight", "gain", "params")


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
                entries += _bind_entries(
                    doc, node, section, registry, robot, path.parent
                )
        q0 = _initial_configuration(doc, robot_spec, robot, root)
        if spec is not INVALID:
            entries += _acceleration_rows(doc, spec, entries, robot, items)
            _check_meshes(doc, spec, root, path.parent)
            _check_allowed_contact(doc, spec, robot, root)
            _check_goal(doc, spec, entries, root, path.parent)
            _check_inputs(doc, spec, entries, root)
            _check_cameras(doc, spec, robot, root)
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
    if not spec.robot.allow_initial_contact:
        _check_initial_contact(doc, scenario, root)
        doc.raise_if_problems()
    for warning in goal_reach_warnings(doc, scenario, root):
        log.warning("%s, %s", doc.path, warning)
    return scenario


def goal_reach_warnings(
    doc: Document, scenario: Scenario, root: yaml.Node
) -> list[str]:
    """A located warning for each keyframe whose goal lies beyond the arm's reach.

    The reach is an upper bound (:mod:`cbp.scenario.reach`): a goal beyond it
    is certainly out of reach, so the arm stops short of it, and no reachable
    goal is warned of. Warnings, not errors: the goal may come back within
    reach at a later keyframe (the arm follows along the reach's edge).
    """
    goal = scenario.spec.goal
    if goal is None or goal.type not in ("keyframes", "step"):
        return []
    reach = scenario.reach()
    if reach is None:
        return []
    nodes = value_node(root, "goal", "keyframes")
    items = nodes.value if isinstance(nodes, yaml.SequenceNode) else []
    warnings = []
    for i, keyframe in enumerate(goal.keyframes):
        why = reach.beyond(np.asarray(keyframe.pose.position, dtype=float))
        if why is not None:
            node = items[i] if i < len(items) else nodes
            warnings.append(
                doc.located(
                    node,
                    f"goal.keyframes[{i}].pose.position",
                    f"the goal {list(keyframe.pose.position)} at t = {keyframe.t:g} s "
                    f"is out of reach of {scenario.ee_frame}: {why}; the arm stops "
                    "short of it",
                )
            )
    return warnings


#: A start deeper than this in a declared object is refused [m].
INITIAL_CONTACT_TOLERANCE = 5e-4


def _check_initial_contact(doc: Document, scenario: Scenario, root: yaml.Node) -> None:
    """Refuse an initial configuration that penetrates a declared object.

    The robot's own shapes, unpadded, against each object (coal's signed
    distance); the deepest overlap of each (link, object) pair is reported.
    """
    objects = scenario.environment_objects()
    if not objects:
        return
    geometry = (
        scenario.world.geometry
        if scenario.world is not None
        else RobotGeometry(scenario.robot)
    )
    state = RobotState(scenario.robot, scenario.q0)
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    deepest: dict[tuple[str, str], float] = {}
    centres, radii = geometry.world_spheres(state)
    fixed = scenario.robot.fixed_links()
    for shape, centre, radius in zip(geometry.shapes, centres, radii, strict=True):
        if shape.link in fixed:
            continue  # no motion leaves it: not checked against obstacles
        placement = shape.world_placement(state)
        for obj in objects:
            if shape.link in obj.allow_contact:
                continue  # wanted contact
            apart = np.any(centre + radius < obj.lower) or np.any(
                centre - radius > obj.upper
            )
            if apart:
                continue
            d = signed_distance(
                obj.shape, obj.placement, shape.shape, placement, request, result
            )[0]
            key = (shape.link, obj.name)
            if d < -INITIAL_CONTACT_TOLERANCE and d < deepest.get(key, 0.0):
                deepest[key] = d
    for (link, name), d in sorted(deepest.items(), key=lambda item: item[1]):
        doc.report(
            value_node(root, "robot", "initial") or value_node(root, "robot"),
            "robot.initial",
            f"the initial configuration puts {link} {-d * 1e3:.1f} mm deep into "
            f"'{name}'; move the robot or the object, or set "
            "robot.allow_initial_contact: true to start in contact (the arm then "
            "backs out)",
        )


def _acceleration_rows(
    doc: Document,
    spec: ScenarioSpec,
    entries: list[Entry],
    robot: RobotModel,
    items: Mapping[str, yaml.Node],
) -> list[Entry]:
    """The robot's acceleration rows, when the step guard checks them and none are.

    A method that gives each step the robot's velocity
    (:attr:`cbp.methods.Method.commands_velocity`) has the step guard refuse
    every answer that accelerates past the robot's limits; a scenario of it
    that lists its own constraints without ``joint_acceleration`` (or another
    entry keeping those limits) would have every step refused and the robot
    never move. The rows are added, at the position limits' margin, and the
    loader says so (a log line; the run an event).
    """
    if not METHODS[spec.method.name].commands_velocity:
        return []
    if any(e.plugin.robot_limit == "acceleration" for e in entries):
        return []
    if not np.isfinite(robot.acceleration_limits).any():
        return []
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
    log.warning("%s, %s", doc.path, plugin.added_because)
    return [Entry.make(plugin)]


def _check_meshes(
    doc: Document, spec: ScenarioSpec, root: yaml.Node, folder: Path
) -> None:
    """Every mesh object's file can be read (regular file, a mesh, triangles)."""
    node = value_node(root, "world", "objects")
    for i, obj in enumerate(spec.world.objects):
        if obj.shape != "mesh":
            continue
        try:
            load_mesh(folder / obj.file)
        except ConfigError as exc:
            item = node.value[i] if isinstance(node, yaml.SequenceNode) else None
            at = value_node(item, "file") if item is not None else None
            doc.report(
                at or node,
                join_path(join_path("world.objects", i), "file"),
                exc.message,
            )


def _check_allowed_contact(
    doc: Document, spec: ScenarioSpec, robot: RobotModel, root: yaml.Node
) -> None:
    """``allow_contact`` names links of the robot."""
    node = value_node(root, "world", "objects")
    links = set(robot.frame_names)
    for i, obj in enumerate(spec.world.objects):
        for link in obj.allow_contact:
            if link not in links:
                item = node.value[i] if isinstance(node, yaml.SequenceNode) else None
                at = value_node(item, "allow_contact") if item is not None else None
                doc.report(
                    at or node,
                    join_path(join_path("world.objects", i), "allow_contact"),
                    f"no link '{link}' in robot '{robot.name}'"
                    f"{suggestion(link, sorted(links))}",
                )


def _check_cameras(
    doc: Document, spec: ScenarioSpec, robot: RobotModel, root: yaml.Node
) -> None:
    """A mounted camera's ``parent`` must be a frame of the robot."""
    key = "cameras" if spec.perception.cameras else "camera"
    node = value_node(root, "perception", key)
    for i, camera in enumerate(spec.perception.all_cameras):
        if camera.parent is None or spec.perception.source != "depth_camera":
            continue
        try:
            robot.frame_id(camera_parent(camera.parent, robot))
        except ConfigError as exc:
            item = node.value[i] if isinstance(node, yaml.SequenceNode) else node
            where = (
                join_path("perception.cameras", i)
                if key == "cameras"
                else "perception.camera"
            )
            parent = value_node(item, "parent") if item is not None else None
            doc.report(parent or item, f"{where}.parent", exc.message)


def _robot_spec_quietly(doc: Document, root: yaml.Node) -> Any:
    """Build the robot section, whose problems were already reported; else INVALID."""
    node = value_node(root, "robot")
    saved = len(doc.problems)
    value = doc.build(RobotSpec, node, "robot") if node is not None else INVALID
    del doc.problems[saved:]
    return value


def _bind_entries(
    doc: Document,
    node: yaml.Node,
    section: str,
    registry: Registry[Any],
    robot: RobotModel,
    folder: Path,
) -> list[Entry]:
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
        if key not in _ENTRY_KEYS:
            doc.report(
                keys.get(key, value),
                join_path(where, key),
                f"unknown key '{key}'{suggestion(key, _ENTRY_KEYS)} Entry keys: "
                f"{', '.join(_ENTRY_KEYS)} (plugin parameters go under 'params').",
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


def _initial_configuration(
    doc: Document, spec: RobotSpec, robot: RobotModel, root: yaml.Node
) -> FloatArray:
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


def _check_goal(
    doc: Document,
    spec: ScenarioSpec,
    entries: list[Entry],
    root: yaml.Node,
    folder: Path,
) -> None:
    goal = spec.goal
    if goal is None:
        return
    if goal.type == "recorded":
        try:
            GoalStream(goal, folder)
        except ConfigError as exc:
            doc.report(value_node(root, "goal", "file"), "goal.file", exc.message)
    if goal.function is not None:
        # Evaluated at every sample the run will take.
        times = run_times(spec.duration, goal.rate_hz)
        for name in ("position", "rpy_deg"):
            for i, text in enumerate(getattr(goal.function, name)):
                where = f"goal.function.{name}[{i}]"
                try:
                    check_over(compile_time_function(text, where), times, where)
                except ConfigError as exc:
                    node = value_node(root, "goal", "function", name)
                    doc.report(node, where, exc.message)
    receivers = goal_receivers(entries, goal.task)
    if len(receivers) != 1:
        tasks = [e.name for e in goal_receivers(entries, None)]
        if goal.task is None and receivers:
            message = (
                f"several tasks can take the goal ({', '.join(tasks)}): name one "
                "with 'task:'"
            )
        elif goal.task is None:
            message = (
                "the goal needs a task that takes a goal pose (such as "
                "'goal_pose'), or 'task:' naming one"
            )
        else:
            message = (
                f"no task named '{goal.task}' takes a goal pose"
                f"{suggestion(goal.task, tasks)} Tasks that do: "
                f"{', '.join(tasks) or '(none)'}."
            )
        doc.report(value_node(root, "goal"), "goal.task", message)


def _check_inputs(
    doc: Document, spec: ScenarioSpec, entries: list[Entry], root: yaml.Node
) -> None:
    takers = {e.name: e.plugin for e in entries if isinstance(e.plugin, TakesInput)}
    node = value_node(root, "inputs")
    for i, item in enumerate(spec.inputs):
        where = f"inputs[{i}]"
        plugin = takers.get(item.entry)
        if plugin is None:
            doc.report(
                node,
                f"{where}.entry",
                f"no entry named '{item.entry}' takes an input"
                f"{suggestion(item.entry, takers)} Entries with inputs: "
                f"{', '.join(takers) or '(none)'}.",
            )
            continue
        size = plugin.input_size
        if len(item.values) != size:
            doc.report(
                node,
                f"{where}.values",
                f"'{item.entry}' takes {size} input value(s), got {len(item.values)}",
            )
        times = run_times(spec.duration, 1.0 / _input_tick(spec))
        for k, value in enumerate(item.values):
            at = f"{where}.values[{k}]"
            try:
                check_over(compile_time_function(value, at), times, at)
            except ConfigError as exc:
                doc.report(node, exc.location, exc.message)


def _input_tick(spec: ScenarioSpec) -> float:
    """How often the operator inputs are sampled [s]: the velocity executor's tick."""
    return spec.method.velocity.dt
