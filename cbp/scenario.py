# SPDX-License-Identifier: Apache-2.0
"""Scenario files: strict YAML loading into typed schemas, then into an engine.

A scenario names the robot, the world, the goal input, the method (executor) and
its settings, and the lists of task and constraint entries. Every entry has the
engine keys ``type``, ``name``, ``priority``, ``weight`` and ``gain``; what the
plugin itself needs goes under ``params``. All problems of a file are reported
together, each with the file, line, path in the document, what was expected and
the nearest valid choice (:class:`~cbp.errors.ScenarioError`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml

from cbp.collision.environment import EnvironmentObject, PrimitiveEnvironment
from cbp.collision.geometry import RobotGeometry
from cbp.collision.world import CollisionSettings, CollisionWorld, UsesCollisionWorld
from cbp.engine import Engine
from cbp.errors import CbpError, ConfigError, ScenarioError, suggestion
from cbp.executors.settings import (
    CatSettings,
    IkSettings,
    JtSettings,
    MpSettings,
    VelocitySettings,
)
from cbp.expressions import TimeFunction, compile_time_function
from cbp.goals import GoalSpec, GoalStream
from cbp.perception.spec import PerceptionSpec
from cbp.plugin import AnyPlugin, Plugin, Task
from cbp.qp import Entry
from cbp.registry import Registry
from cbp.robot import BaseType, FloatArray, RobotModel
from cbp.schema import INVALID, Document, join_path, mapping_items
from cbp.sim.settings import ObjectSpec, SimulationSettings

__all__ = [
    "MethodSpec",
    "ObjectSpec",
    "RobotSpec",
    "Scenario",
    "ScenarioSpec",
    "SolverSpec",
    "WorldSpec",
    "load_scenario",
]

#: Executors ``cbp run --method`` accepts.
MethodName = Literal["kinematic", "cat", "ik", "mp", "jt", "velocity"]


@dataclass(frozen=True, kw_only=True)
class RobotSpec:
    """The ``robot:`` section."""

    name: str
    """Robot folder under ``robots/`` (or a path to one)."""
    base: BaseType | None = None
    """``fixed``, ``planar`` (x, y, yaw) or ``floating``; default: the robot's
    own (robot.yaml's ``base``)."""
    initial: dict[str, float] = field(default_factory=dict)
    """Initial joint positions by name [rad or m]; others start at home."""


@dataclass(frozen=True, kw_only=True)
class SolverSpec:
    """The ``solver:`` section."""

    name: Literal["daqp", "piqp", "cvxpy"] = "daqp"
    """QP backend."""
    regularization: float = 1e-9
    """Added to the diagonal of the QP cost matrix."""

    def __post_init__(self) -> None:
        """Regularization must be positive."""
        if not self.regularization > 0:
            raise ConfigError(
                f"must be > 0, got {self.regularization}", "regularization"
            )


@dataclass(frozen=True, kw_only=True)
class MethodSpec:
    """The ``method:`` section: which executor runs the scenario, and its timing."""

    name: MethodName = "kinematic"
    """``kinematic``: integrate each QP step exactly (no simulator); ``cat``:
    constraint-aware teleoperation in the simulator (many validated QP steps per
    command period, spliced trajectories); ``ik``, ``mp``, ``jt``: the CAT
    paper's alternatives (collision-aware IK, motion planning, Jacobian
    transpose); ``velocity``: one QP per control tick, velocities sent to a
    mobile manipulator (orbit object, pan object)."""
    dt: float = 0.01
    """``kinematic``: duration of one control step [s]."""
    cat: CatSettings = field(default_factory=CatSettings)
    """Settings of the CAT executor."""
    ik: IkSettings = field(default_factory=IkSettings)
    """Settings of the collision-aware IK executor."""
    mp: MpSettings = field(default_factory=MpSettings)
    """Settings of the motion-planning executor."""
    jt: JtSettings = field(default_factory=JtSettings)
    """Settings of the Jacobian-transpose executor."""
    velocity: VelocitySettings = field(default_factory=VelocitySettings)
    """Settings of the velocity executor (mobile manipulators, orbit object)."""

    def __post_init__(self) -> None:
        """Positive step."""
        if not self.dt > 0:
            raise ConfigError(f"must be > 0, got {self.dt}", "dt")


@dataclass(frozen=True, kw_only=True)
class InputSpec:
    """One live operator input: values for an entry's ``set_input``, as functions of t.

    The orbit's user velocity and desired distance are inputs; so is anything a
    plugin exposes through ``set_input``.
    """

    entry: str
    """Name of the task or constraint entry that takes the input."""
    values: list[str | float]
    """One number or expression of ``t`` per input value (see
    :mod:`cbp.expressions`)."""


@dataclass(frozen=True, kw_only=True)
class WorldSpec:
    """The ``world:`` section: the objects around the robot."""

    objects: list[ObjectSpec] = field(default_factory=list)
    """Objects, in the world frame."""


@dataclass(frozen=True, kw_only=True)
class ScenarioSpec:
    """A whole scenario file (tasks and constraints are bound separately)."""

    name: str
    """Scenario name, used for output folders."""
    description: str = ""
    """What the scenario shows."""
    robot: RobotSpec
    """The robot."""
    duration: float
    """Length of a run [s]."""
    method: MethodSpec = field(default_factory=MethodSpec)
    """The executor and its timing."""
    solver: SolverSpec = field(default_factory=SolverSpec)
    """The QP backend."""
    goal: GoalSpec | None = None
    """The goal input, if any."""
    world: WorldSpec = field(default_factory=WorldSpec)
    """The objects around the robot."""
    simulation: SimulationSettings = field(default_factory=SimulationSettings)
    """Physics rate and the joint impedance of the simulated robot."""
    collision: CollisionSettings = field(default_factory=CollisionSettings)
    """Contact queries and step validation."""
    perception: PerceptionSpec = field(default_factory=PerceptionSpec)
    """Where the collision world's environment comes from."""
    inputs: list[InputSpec] = field(default_factory=list)
    """Live operator inputs to entries (velocity executor), functions of time."""
    tasks: Any = None
    """Task entries (bound by :func:`load_scenario`)."""
    constraints: Any = None
    """Constraint entries (bound by :func:`load_scenario`)."""

    def __post_init__(self) -> None:
        """Positive duration."""
        if not self.duration > 0:
            raise ConfigError(f"must be > 0, got {self.duration}", "duration")


_ENTRY_KEYS = ("type", "name", "priority", "weight", "gain", "params")


@dataclass
class Scenario:
    """A loaded scenario: its schema, the robot, and the bound entries.

    Attributes:
        path: the file it came from.
        spec: the parsed schema.
        robot: the loaded robot model.
        entries: tasks then constraints, with their engine settings.
        q0: the initial configuration.
    """

    path: Path
    spec: ScenarioSpec
    robot: RobotModel
    entries: list[Entry]
    q0: FloatArray
    _world: CollisionWorld | None = field(default=None, repr=False)

    @property
    def needs_collision_world(self) -> bool:
        """Whether some entry reads contacts."""
        return any(isinstance(e.plugin, UsesCollisionWorld) for e in self.entries)

    def environment_objects(self) -> list[EnvironmentObject]:
        """The declared objects as collision objects (mesh files resolved)."""
        objects = []
        for obj in self.spec.world.objects:
            placement = obj.pose.to_se3()
            if obj.shape == "mesh":
                objects.append(
                    EnvironmentObject.mesh(
                        obj.name,
                        self.path.parent / obj.file,
                        np.asarray(obj.scale),
                        placement,
                    )
                )
            else:
                objects.append(
                    EnvironmentObject.primitive(
                        obj.name, obj.shape, obj.size, placement
                    )
                )
        return objects

    def collision_world(self) -> CollisionWorld:
        """The scenario's collision world (built once), attached to its plugins.

        Its environment is the declared objects; an executor with a depth camera
        replaces it with occupancy-map snapshots as they come.
        """
        if self._world is None:
            geometry = RobotGeometry(self.robot, padding=self.spec.collision.padding)
            environment = PrimitiveEnvironment(self.environment_objects())
            self._world = CollisionWorld(geometry, environment, self.spec.collision)
            for entry in self.entries:
                if isinstance(entry.plugin, UsesCollisionWorld):
                    entry.plugin.attach_world(self._world)
        return self._world

    def make_engine(self) -> Engine:
        """A fresh engine for these entries (plugins are shared, not copied)."""
        return Engine(
            self.robot,
            self.entries,
            solver=self.spec.solver.name,
            regularization=self.spec.solver.regularization,
        )

    def goal_stream(self) -> GoalStream | None:
        """The goal stream, if the scenario has one."""
        if self.spec.goal is None:
            return None
        return GoalStream(self.spec.goal, self.path.parent)

    def inputs(self) -> list[tuple[AnyPlugin, list[TimeFunction]]]:
        """Each input's plugin and its compiled functions of time."""
        by_name = {e.name: e.plugin for e in self.entries}
        return [
            (
                by_name[spec.entry],
                [
                    compile_time_function(v, f"inputs[{i}].values[{k}]")
                    for k, v in enumerate(spec.values)
                ],
            )
            for i, spec in enumerate(self.spec.inputs)
        ]

    def goal_task(self) -> Task[Any] | None:
        """The task entry that receives the goal (checked at load time)."""
        goal = self.spec.goal
        if goal is None:
            return None
        for entry in self.entries:
            if _receives_goal(entry.plugin, goal.task):
                assert isinstance(entry.plugin, Task)
                return entry.plugin
        return None  # pragma: no cover - load_scenario rejects this


def _receives_goal(plugin: AnyPlugin, name: str | None) -> bool:
    if name is not None:
        return plugin.name == name
    return plugin.type_name == "goal_pose"


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
        tasks: task registry (default: the in-tree ``plugins.tasks.TASKS``).
        constraints: constraint registry (default ``plugins.constraints.CONSTRAINTS``).

    Raises:
        ScenarioError: listing every problem in the file.
    """
    from plugins.constraints import CONSTRAINTS
    from plugins.tasks import TASKS

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
            robot = RobotModel.load(robot_spec.name, base=robot_spec.base)
        except CbpError as exc:
            doc.report(_key_node(root, "robot", "name"), "robot.name", str(exc))
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
            _check_goal(doc, spec, entries, root, path.parent)
            _check_inputs(doc, spec, entries, root)
        names = [e.name for e in entries]
        for name in sorted({n for n in names if names.count(n) > 1}):
            doc.report(
                None,
                "tasks/constraints",
                f"entry name '{name}' is used twice; give each entry its own 'name'",
            )
    doc.raise_if_problems()
    assert robot is not None
    scenario = Scenario(path=path, spec=spec, robot=robot, entries=entries, q0=q0)
    if scenario.needs_collision_world:
        try:
            scenario.collision_world()
        except ConfigError as exc:
            where = f" ({exc.location})" if exc.location else ""
            raise ScenarioError(
                str(path), [f"collision world{where}: {exc.message}"]
            ) from exc
    return scenario


def _robot_spec_quietly(doc: Document, root: yaml.Node) -> Any:
    """Build the robot section, whose problems were already reported; else INVALID."""
    node = _key_node(root, "robot")
    saved = len(doc.problems)
    value = doc.build(RobotSpec, node, "robot") if node is not None else INVALID
    del doc.problems[saved:]
    return value


def _key_node(root: yaml.Node, *keys: str) -> yaml.Node | None:
    node: yaml.Node | None = root
    for key in keys:
        if not isinstance(node, yaml.MappingNode):
            return None
        node = next(
            (
                v
                for k, v in node.value
                if isinstance(k, yaml.ScalarNode) and k.value == key
            ),
            None,
        )
    return node


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
    for key, value in items.items():
        if key not in _ENTRY_KEYS:
            doc.report(
                value,
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
        key_node = _key_node(node, "params", *exc.location.split(".")[:1])
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
            q0[robot.joint_q_slice(joint)] = value
        except ConfigError as exc:
            doc.report(
                _key_node(root, "robot", "initial", joint),
                f"robot.initial.{joint}",
                exc.message,
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
            doc.report(_key_node(root, "goal", "file"), "goal.file", exc.message)
    receivers = [e for e in entries if _receives_goal(e.plugin, goal.task)]
    if not receivers or not hasattr(receivers[0].plugin, "set_target"):
        tasks = [e.name for e in entries if isinstance(e.plugin, Task)]
        if goal.task is None:
            message = "the goal needs a 'goal_pose' task, or 'task:' naming the task"
        else:
            message = (
                f"no task named '{goal.task}' with a pose target"
                f"{suggestion(goal.task, tasks)} Tasks: {', '.join(tasks) or '(none)'}."
            )
        doc.report(_key_node(root, "goal"), "goal.task", message)


def _check_inputs(
    doc: Document, spec: ScenarioSpec, entries: list[Entry], root: yaml.Node
) -> None:
    by_name = {e.name: e.plugin for e in entries}
    node = _key_node(root, "inputs")
    for i, item in enumerate(spec.inputs):
        where = f"inputs[{i}]"
        plugin = by_name.get(item.entry)
        if plugin is None or not hasattr(plugin, "set_input"):
            takers = [n for n, p in by_name.items() if hasattr(p, "set_input")]
            doc.report(
                node,
                f"{where}.entry",
                f"no entry named '{item.entry}' takes an input"
                f"{suggestion(item.entry, takers)} Entries with inputs: "
                f"{', '.join(takers) or '(none)'}.",
            )
            continue
        size = int(getattr(plugin, "input_size", 0))
        if len(item.values) != size:
            doc.report(
                node,
                f"{where}.values",
                f"'{item.entry}' ({plugin.type_name}) takes {size} input value(s), "
                f"got {len(item.values)}",
            )
        for k, value in enumerate(item.values):
            try:
                compile_time_function(value, f"{where}.values[{k}]")
            except ConfigError as exc:
                doc.report(node, exc.location, exc.message)
