# SPDX-License-Identifier: Apache-2.0
"""A loaded scenario: the robot, the bound entries, and what executors build from them.

:class:`Scenario` is what :func:`cbp.scenario.load_scenario` returns and every
executor takes: the parsed schema, the robot model, the task and constraint
entries, the initial configuration, and factories for the engine, the collision
world, the goal stream and the operator inputs.
"""

from __future__ import annotations

import dataclasses
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
from cbp.goals import GoalStream
from cbp.perception.camera import camera_parent
from cbp.plugin import GoalReceiver, TakesInput, Task, UsesCollisionWorld
from cbp.qp import Entry
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.spec import ScenarioSpec

__all__ = ["Scenario", "goal_receivers"]


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

    def environment_objects(self, t: float = 0.0) -> list[EnvironmentObject]:
        """The declared objects as collision objects (mesh files resolved).

        Those in the scene at time ``t`` [s], where they are then and with their
        velocity then (``appear_at``, ``motion``).
        """
        objects = []
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
            if obj.allow_contact:
                made = dataclasses.replace(
                    made, allow_contact=frozenset(obj.allow_contact)
                )
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

    def collision_world(self) -> CollisionWorld:
        """The scenario's collision world (built once), attached to its plugins.

        Its environment is the declared objects; an executor with a depth camera
        replaces it with occupancy-map snapshots as they come. The robot's
        shapes include :meth:`attachments`.
        """
        if self._world is None:
            geometry = RobotGeometry(
                self.robot,
                padding=self.spec.collision.padding,
                attachments=self.attachments(),
            )
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


def goal_receivers(entries: list[Entry], name: str | None) -> list[Any]:
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
