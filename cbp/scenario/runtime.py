# SPDX-License-Identifier: Apache-2.0
"""A loaded scenario: the robot, the bound entries, and what a run is built from.

:class:`Scenario` is what :func:`cbp.scenario.load_scenario` returns and every
executor takes: frozen data (the parsed schema, the robot model, the task and
constraint entries, the initial configuration, and the collision world the
entries that read contacts are attached to), with factories that build new
things from it and change nothing (an engine, another collision world, the
goal stream, the operator inputs). A run is assembled from it by
:func:`cbp.run.build_run`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from cbp.collision.geometry import Attachment, RobotGeometry
from cbp.collision.objects import EnvironmentObject, PrimitiveEnvironment
from cbp.collision.world import CollisionWorld
from cbp.engine import Engine
from cbp.expressions import TimeFunction, compile_time_function
from cbp.goals import GoalStream, goal_stream
from cbp.perception.frame import camera_parent
from cbp.plugin import GoalReceiver, TakesInput, Task, UsesCollisionWorld
from cbp.qp import Entry
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.reach import Reach, arm_reach
from cbp.scenario.spec import ScenarioSpec

__all__ = ["Scenario", "goal_receivers"]


@dataclass(frozen=True)
class Scenario:
    """A loaded scenario: its schema, the robot, and the bound entries.

    Attributes:
        path: the file it came from.
        spec: the parsed schema.
        robot: the loaded robot model.
        entries: tasks then constraints, with their engine settings.
        q0: the initial configuration.
        world: the collision world the entries that read contacts are
            attached to (made by :func:`~cbp.scenario.load_scenario`; None
            when no entry reads contacts). Its environment is the declared
            objects; a run with cameras replaces it with the map's snapshots.
    """

    path: Path
    spec: ScenarioSpec
    robot: RobotModel
    entries: tuple[Entry, ...]
    q0: FloatArray
    world: CollisionWorld | None = field(default=None, repr=False)

    @property
    def needs_collision_world(self) -> bool:
        """Whether some entry reads contacts."""
        return any(isinstance(e.plugin, UsesCollisionWorld) for e in self.entries)

    def world_for_run(self) -> CollisionWorld:
        """The world a run checks against: the entries' own, else a new one."""
        return self.world if self.world is not None else self.new_world()

    def environment_objects(self, t: float = 0.0) -> list[EnvironmentObject]:
        """The declared objects as collision objects (mesh files resolved).

        Those in the scene at time ``t`` [s], where they are then and with their
        velocity then (``appear_at``, ``motion``).
        """
        objects = []
        fixed = self.robot.fixed_links()
        for obj in self.spec.world.objects:
            if not obj.present(t):
                continue
            placement = obj.placement_at(t)
            if obj.shape == "mesh":
                made = EnvironmentObject.mesh(
                    obj.name,
                    self.path.parent / obj.file,
                    np.asarray(obj.scale),
                    placement,
                )
            else:
                made = EnvironmentObject.primitive(
                    obj.name, obj.shape, obj.size, placement
                )
            allowed = frozenset(obj.allow_contact) | fixed
            if allowed:
                made = dataclasses.replace(made, allow_contact=allowed)
            if obj.motion is not None:
                made = dataclasses.replace(made, velocity=obj.velocity_at(t))
            objects.append(made)
        return objects

    def attachments(self) -> list[Attachment]:
        """Bodies on the robot beyond its URDF: mounted cameras' housings.

        Only while the cameras are in use (``perception.source: depth_camera``).
        """
        perception = self.spec.perception
        if perception.source != "depth_camera":
            return []
        bodies = []
        for camera in perception.all_cameras:
            if camera.parent is None or camera.body is None:
                continue
            width, height, depth = camera.body
            behind = pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.5 * depth]))
            bodies.append(
                Attachment(
                    name=f"camera_{camera.name}",
                    frame=camera_parent(camera.parent, self.robot),
                    placement=camera.offset.to_se3() * behind,
                    shape=coal.Box(width, height, depth),
                )
            )
        return bodies

    def new_world(self) -> CollisionWorld:
        """A new collision world of this scenario, attached to nothing.

        The robot's padded shapes (with :meth:`attachments`) against the
        declared objects as they are at time 0.
        """
        geometry = RobotGeometry(
            self.robot,
            padding=self.spec.collision.padding,
            attachments=self.attachments(),
        )
        environment = PrimitiveEnvironment(self.environment_objects())
        return CollisionWorld(geometry, environment, self.spec.collision)

    def bound(self) -> Scenario:
        """This scenario with fresh plugins and a fresh collision world, for one run.

        The scenario is data: each run binds its own plugin instances (their
        targets and latches) from the same parameters, and its own world, so
        one :class:`Scenario` runs any number of times with the same result.
        """
        entries = tuple(
            dataclasses.replace(e, plugin=_rebound(e.plugin, self.robot))
            for e in self.entries
        )
        world = None
        if self.world is not None:
            world = self.new_world()
            for entry in entries:
                if isinstance(entry.plugin, UsesCollisionWorld):
                    entry.plugin.attach_world(world)
        return dataclasses.replace(self, entries=entries, world=world)

    def make_engine(self) -> Engine:
        """A new engine for these entries.

        The plugins are the scenario's (shared, not copied: their targets and
        latches are the scenario's), so engines of one scenario step one at a
        time.
        """
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
        return goal_stream(self.spec.goal, self.path.parent)

    def inputs(self) -> list[tuple[TakesInput, list[TimeFunction]]]:
        """Each input's plugin and its compiled functions of time."""
        by_name = {
            e.name: e.plugin for e in self.entries if isinstance(e.plugin, TakesInput)
        }
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

    def goal_task(self) -> GoalReceiver | None:
        """The task entry that receives the goal (checked at load time)."""
        goal = self.spec.goal
        if goal is None:
            return None
        receivers = goal_receivers(self.entries, goal.task)
        return receivers[0] if receivers else None

    @property
    def ee_frame(self) -> str:
        """The frame that tracks the goal: the goal task's, else the end effector."""
        task = self.goal_task()
        if task is not None:
            return task.goal_frame
        return self.robot.end_effector

    def reach(self) -> Reach | None:
        """How far the goal's frame can get from the arm's first joint.

        None for a robot whose base moves or with a prismatic joint on the
        chain (:func:`~cbp.scenario.reach.arm_reach`).
        """
        return arm_reach(self.robot, self.q0, self.ee_frame)


def _rebound(plugin: Any, robot: RobotModel) -> Any:
    """A new instance of ``plugin``, bound from the same parameters.

    What the loader said of an entry it added (``added_because``) stays.
    """
    fresh = type(plugin)(plugin.params, robot, plugin.name)
    added = getattr(plugin, "added_because", None)
    if added is not None:
        fresh.added_because = added
    return fresh


def goal_receivers(entries: Sequence[Entry], name: str | None) -> list[Any]:
    """The task entries that can take the goal.

    The one named ``name``, or every :class:`~cbp.plugin.GoalReceiver` task
    when no name is given.
    """
    return [
        e.plugin
        for e in entries
        if isinstance(e.plugin, Task)
        and isinstance(e.plugin, GoalReceiver)
        and (name is None or e.name == name)
    ]
