# SPDX-License-Identifier: Apache-2.0
"""What a scenario is checked for once its robot and entries are there.

Each check records its problems in the document, located at the key they are
about; the warnings (a goal beyond the arm's reach, an object faster than the
arm can retreat from) are returned, located, for the loader to log.
"""

from __future__ import annotations

from pathlib import Path

import coal
import numpy as np
import yaml

from cbp.collision.environment import signed_distance
from cbp.collision.geometry import RobotGeometry
from cbp.errors import ConfigError, DataFileError, suggestion
from cbp.expressions import check_over, compile_time_function, run_times
from cbp.files import load_mesh
from cbp.goals import KeyframesGoalSpec, goal_stream
from cbp.perception.frame import camera_parent
from cbp.plugin import TakesInput
from cbp.qp import Entry
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.runtime import Scenario, goal_receivers
from cbp.scenario.spec import ScenarioSpec
from cbp.schema import Document, join_path, node_at, value_node
from cbp.state import RobotState

__all__ = [
    "ALLOWED_INITIAL_DEPTH",
    "INITIAL_CONTACT_TOLERANCE",
    "check_allowed_contact",
    "check_cameras",
    "check_goal",
    "check_initial_contact",
    "check_inputs",
    "check_meshes",
    "goal_reach_warnings",
    "object_speed_warnings",
]


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
    if not isinstance(goal, KeyframesGoalSpec):  # keyframes and step
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


def object_speed_warnings(
    doc: Document, scenario: Scenario, root: yaml.Node
) -> list[str]:
    """A located warning for each moving object the arm cannot retreat from.

    The bound of speed and separation monitoring, as the run measures it as
    objects come (:class:`cbp.run.separation.DeclaredSeparationMonitor`): the
    arm, retreating along the object's path u at its joints' velocity limits,
    moves a point p at most sum_j |u . J_j(p)| v_max,j (J: the point's
    Jacobian). Taken at the arm's part nearest the path in the initial
    configuration: an object faster than that meets the arm there whatever it
    does. Warnings, not errors: a scenario may want an arm pressed (the run
    says so, and measures the force).
    """
    moving = [
        (i, obj)
        for i, obj in enumerate(scenario.spec.world.objects)
        if obj.motion is not None and any(obj.motion.velocity)
    ]
    robot = scenario.robot
    geometry = (
        scenario.world.geometry
        if scenario.world is not None
        else RobotGeometry(robot)
        if moving
        else None
    )
    if geometry is None:
        return []
    state = RobotState(robot, scenario.q0)
    centres, radii = geometry.world_spheres(state)
    fixed = robot.fixed_links()
    parts = [k for k, shape in enumerate(geometry.shapes) if shape.link not in fixed]
    nodes = value_node(root, "world", "objects")
    warnings = []
    for i, obj in moving:
        assert obj.motion is not None
        velocity = np.asarray(obj.motion.velocity, dtype=float)
        speed = float(np.linalg.norm(velocity))
        start = obj.placement_at(obj.motion.start).translation
        end = obj.placement_at(obj.motion.stop).translation
        k = min(
            parts,
            key=lambda k: _segment_distance(centres[k], start, end) - radii[k],
            default=None,
        )
        if k is None:
            continue
        link = geometry.shapes[k].link
        J = state.point_jacobian(robot.frame_id(link), centres[k])
        along = np.abs((velocity / speed) @ J)
        # A joint that does not move the point counts 0, whatever its limit.
        rates = np.multiply(
            along, robot.velocity_limits, out=np.zeros_like(along), where=along > 0.0
        )
        top = float(np.sum(rates))
        if speed <= top:
            continue
        item = nodes.value[i] if isinstance(nodes, yaml.SequenceNode) else None
        warnings.append(
            doc.located(
                node_at(item, "motion.velocity") or item,
                f"world.objects[{i}].motion.velocity",
                f"'{obj.name}' moves at {speed:.3g} m/s, faster than the arm can "
                f"retreat along its path (at most {top:.3g} m/s at {link}, the "
                "arm's part nearest the path at the start, at the joints' "
                "velocity limits): where it meets the arm, contact is possible",
            )
        )
    return warnings


def _segment_distance(point: FloatArray, a: FloatArray, b: FloatArray) -> float:
    """Distance from ``point`` to the segment from ``a`` to ``b`` [m]."""
    ab = b - a
    s = float(np.clip((point - a) @ ab / max(float(ab @ ab), 1e-18), 0.0, 1.0))
    return float(np.linalg.norm(point - (a + s * ab)))


#: A start deeper than this in a declared object is refused [m].
INITIAL_CONTACT_TOLERANCE = 5e-4
#: ... and with ``robot.allow_initial_contact``, a start deeper than this [m].
#: Measured with CAT on the pushed-box scene (a box into the arm's lowest
#: point, the virtual clock): out of contact 0.16 s after a 1.9 cm start and
#: 0.46 s after 3.7 cm; a 6.1 cm start was never left in 3 s (the deepest
#: points' normals no longer lead out, and the simulator pushes with kN).
ALLOWED_INITIAL_DEPTH = 0.04


def check_initial_contact(doc: Document, scenario: Scenario, root: yaml.Node) -> None:
    """Refuse an initial configuration that penetrates a declared object.

    The robot's own shapes, unpadded, against each object (coal's signed
    distance); the deepest overlap of each (link, object) pair is reported.
    With ``robot.allow_initial_contact`` only a start deeper than
    :data:`ALLOWED_INITIAL_DEPTH`, which backing out cannot leave.
    """
    allowed = scenario.spec.robot.allow_initial_contact
    tolerance = ALLOWED_INITIAL_DEPTH if allowed else INITIAL_CONTACT_TOLERANCE
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
            if d < -tolerance and d < deepest.get(key, 0.0):
                deepest[key] = d
    for (link, name), d in sorted(deepest.items(), key=lambda item: item[1]):
        where = (
            f"the initial configuration puts {link} {-d * 1e3:.1f} mm deep "
            f"into '{name}'"
        )
        doc.report(
            value_node(root, "robot", "initial") or value_node(root, "robot"),
            "robot.initial",
            (
                f"{where}, deeper than the {ALLOWED_INITIAL_DEPTH * 1e3:.0f} mm "
                "an arm backs out of (robot.allow_initial_contact); move the "
                "robot or the object"
            )
            if allowed
            else f"{where}; move the robot or the object, or set "
            "robot.allow_initial_contact: true to start in contact (the arm then "
            "backs out)",
        )


def check_meshes(
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


def check_allowed_contact(
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


def check_cameras(
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


def check_goal(
    doc: Document,
    spec: ScenarioSpec,
    entries: list[Entry],
    root: yaml.Node,
    folder: Path,
) -> None:
    """The goal can be sampled over the run, and one task takes it."""
    goal = spec.goal
    if goal is None:
        return
    try:
        failures = goal_stream(goal, folder).problems(spec.duration)
    except ConfigError as exc:
        failures = [exc]
    for failure in failures:
        at = join_path("goal", failure.location)
        said = (  # a file's problems, each at its row and column there
            [f"{failure.path}, {problem}" for problem in failure.problems]
            if isinstance(failure, DataFileError)
            else [failure.message]
        )
        for message in said:
            doc.report(node_at(root, at), at, message)
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


def check_inputs(
    doc: Document, spec: ScenarioSpec, entries: list[Entry], root: yaml.Node
) -> None:
    """Each input names an entry that takes inputs, with one value per input."""
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
