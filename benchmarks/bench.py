# SPDX-License-Identifier: Apache-2.0
"""``cbp bench``: where the time goes, against peers and against the limit.

Every row runs in this process, one after the other, so that the ratios between
rows hold on a noisy machine; absolute times differ between machines. Each row
is the median and 95th percentile of many repetitions after a warm-up. Rows:

1. one engine step of the Panda's reaching task (goal pose, posture, joint step,
   joint position and velocity limits), daqp, piqp and cvxpy backends;
2. the same task on peers: pink (``solve_ik``, daqp), mink (``solve_ik`` on
   MuJoCo, daqp), placo (``KinematicsSolver``) and a hand-written pinocchio +
   numpy + daqp step;
3. one CAT step with collisions (kinematics, contact query, contact rows, QP,
   step validation) on the boards scene and against an octree of the shelf,
   and on the boards with each narrow phase (compiled, coal);
4. scaling with contact rows and with the size of the scene and of the map;
5. MP planning in the shelf, one orbit tick, one map update;
6. whole CAT runs on the virtual clock, with cameras and declared objects;
7. one depth frame per renderer (PyBullet's tiny renderer, the ray cast,
   MuJoCo's), and CAT runs on MuJoCo with cameras against their twins.

Peers (pink, mink, placo) are bench extras: ``pip install -e ".[bench]"``.
"""

from __future__ import annotations

import cProfile
import gc
import importlib
import io
import json
import os
import platform
import pstats
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

# MuJoCo's OpenGL back end (EGL) is chosen here, before any row (a peer on
# MuJoCo too) imports mujoco: after, it could not be.
import cbp.sim.mujoco  # noqa: F401

__all__ = [
    "TARGETS",
    "BenchConfig",
    "Row",
    "frame_rows",
    "mujoco_run_rows",
    "narrow_phase_rows",
    "run_bench",
    "targets_table",
    "write_results",
]

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
DT = 0.01
WEIGHTS = np.array([1.0, 1.0, 1.0, 0.3, 0.3, 0.3])
GOALS = [
    pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0.0, yaw), np.array(p))
    for yaw, p in [
        (0.0, [0.5, 0.2, 0.4]),
        (0.5, [0.4, -0.3, 0.5]),
        (-0.4, [0.6, 0.0, 0.2]),
    ]
]
PERIOD = 1.0 / 30.0


@dataclass(frozen=True)
class BenchConfig:
    """How many repetitions; ``quick`` runs in under two minutes."""

    repetitions: int = 3000
    """Repetitions of a fast row (slower rows use fewer)."""
    warmup: int = 200
    """Calls before timing."""
    mp_seeds: int = 20
    """Planning runs for the MP row (one seed for the process, fresh samples
    per run)."""

    @classmethod
    def quick(cls) -> BenchConfig:
        """Fewer repetitions: every row, in under two minutes."""
        return cls(repetitions=400, warmup=50, mp_seeds=5)

    @classmethod
    def tiny(cls) -> BenchConfig:
        """A handful of repetitions, to keep the benchmark working in tests."""
        return cls(repetitions=5, warmup=2, mp_seeds=1)


@dataclass
class Row:
    """One measured case.

    Attributes:
        group: the table it belongs to.
        case: what was timed.
        median_us: median wall time per call [us].
        p95_us: 95th percentile [us].
        n: repetitions.
        ratio_to: the row the ratio is taken against (same group), if any.
        ratio: median / that row's median.
        note: what the row includes.
    """

    group: str
    case: str
    median_us: float
    p95_us: float
    n: int
    ratio_to: str = ""
    ratio: float | None = None
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def per_period(self) -> float:
        """Calls that fit in a 33 ms command period."""
        return PERIOD * 1e6 / self.median_us if self.median_us > 0 else float("inf")


def measure(fn: Callable[[int], object], n: int, warmup: int) -> tuple[float, float]:
    """Median and 95th percentile [us] of ``fn(i)`` over ``n`` calls after a warm-up."""
    for i in range(warmup):
        fn(i)
    samples = np.empty(n)
    gc.disable()
    try:
        for i in range(n):
            start = time.perf_counter()
            fn(i)
            samples[i] = time.perf_counter() - start
    finally:
        gc.enable()
    return float(np.median(samples) * 1e6), float(np.percentile(samples, 95) * 1e6)


def measure_interleaved(
    fns: list[Callable[[int], object]],
    n: int,
    warmup: int,
    rounds: int = 20,
    clock: Callable[[], float] = time.perf_counter,
) -> list[tuple[float, float]]:
    """Like :func:`measure` for several functions, in alternating rounds.

    Each function runs ``n // rounds`` calls per round, the functions taking
    turns, so that a slow spell of the machine (another process, the CPU's
    clock) falls on all of them alike and their ratios hold. ``clock``:
    wall time by default, ``time.process_time`` for the process's CPU time
    (all its threads).
    """
    for fn in fns:
        for i in range(warmup):
            fn(i)
    per_round = max(n // rounds, 1)
    samples = [np.empty(per_round * rounds) for _ in fns]
    gc.disable()
    try:
        for r in range(rounds):
            for fn, out in zip(fns, samples, strict=True):
                for j in range(per_round):
                    i = r * per_round + j
                    start = clock()
                    fn(i)
                    out[i] = clock() - start
    finally:
        gc.enable()
    return [
        (float(np.median(x) * 1e6), float(np.percentile(x, 95) * 1e6)) for x in samples
    ]


# ---------------------------------------------------------------- 1-2: reaching


def _engine(robot: Any, solver: str) -> tuple[Any, Any]:
    from cbp.engine import Engine
    from cbp.plugins.constraints.joint_limits_constraint import (
        JointLimitsConstraint,
        JointLimitsParams,
    )
    from cbp.plugins.constraints.joint_velocity_constraint import (
        JointVelocityConstraint,
        JointVelocityParams,
    )
    from cbp.plugins.tasks.goal_pose_task import GoalPoseParams, GoalPoseTask
    from cbp.plugins.tasks.joint_step_task import JointStepParams, JointStepTask
    from cbp.plugins.tasks.posture_task import PostureParams, PostureTask
    from cbp.qp import Entry

    goal = GoalPoseTask(GoalPoseParams(frame="panda_hand", clip="independent"), robot)
    entries = [
        Entry.make(goal, weight=WEIGHTS),
        Entry.make(JointStepTask(JointStepParams(), robot), weight=1e-3),
        Entry.make(PostureTask(PostureParams(), robot), weight=1e-4, gain=0.1),
        Entry.make(JointLimitsConstraint(JointLimitsParams(margin=0.02), robot)),
        Entry.make(JointVelocityConstraint(JointVelocityParams(scale=0.5), robot)),
    ]
    return Engine(robot, entries, solver=solver), goal


class HandWritten:
    """The reaching step without a framework: pinocchio + numpy + daqp, with care."""

    def __init__(self, robot: Any) -> None:
        """Precompute everything that does not change between steps."""
        self.model = robot.model
        self.data = robot.model.createData()
        self.frame = robot.frame_id("panda_hand")
        self.lower = robot.lower_limits + 0.02
        self.upper = robot.upper_limits - 0.02
        self.middle = 0.5 * (robot.lower_limits + robot.upper_limits)
        self.reach = 0.5 * robot.velocity_limits * DT
        self.sqrt_w = np.sqrt(WEIGHTS)
        self.H_const = (1e-3 + 1e-4 + 1e-9) * np.eye(robot.nv)
        self.A = np.eye(robot.nv)
        self.sense = np.zeros(robot.nv, dtype=np.int32)
        self.goal = GOALS[0]

    def step(self, q: np.ndarray) -> np.ndarray:
        """Return dq for one step from q."""
        import daqp

        model, data, fid = self.model, self.data, self.frame
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        placement = data.oMf[fid]
        J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
        M = placement.rotation.dot(self.goal.rotation.T)
        e = np.empty(6)
        e[:3] = placement.translation - self.goal.translation
        e[3:] = pin.log3(M)
        J[3:] = pin.Jlog3(M).dot(M.T).dot(J[3:])
        desired = -e
        n = np.linalg.norm(desired[:3])
        if n > 0.01:
            desired[:3] *= 0.01 / n
        n = np.linalg.norm(desired[3:])
        if n > 0.05:
            desired[3:] *= 0.05 / n
        Jw = J * self.sqrt_w[:, None]
        H = Jw.T.dot(Jw) + self.H_const
        g = -Jw.T.dot(desired * self.sqrt_w) + 1e-4 * 0.1 * (q - self.middle)
        lower = np.maximum(self.lower - q, -self.reach)
        upper = np.minimum(self.upper - q, self.reach)
        x, _, _, _ = daqp.solve(H, g, self.A, upper, lower, self.sense)
        return np.asarray(x)

    def stepper(self, q0: np.ndarray) -> Callable[[int], object]:
        """Call ``i`` of a reach from ``q0``, as the benchmarks time it.

        Each call steps from where the last one left the arm, toward
        ``GOALS[(i // 64) % len(GOALS)]``, and returns dq.
        """
        current = {"q": q0.copy()}

        def step(i: int) -> object:
            self.goal = GOALS[(i // 64) % len(GOALS)]
            dq = self.step(current["q"])
            current["q"] = pin.integrate(self.model, current["q"], dq)
            return dq

        return step


#: A step to time: (case, function of the call index, note).
Step = tuple[str, Callable[[int], object], str]


def _reaching_rows(cfg: BenchConfig) -> list[Row]:
    """The reaching step: ours on each backend, pink, mink, placo, hand-written.

    Every row but cvxpy's (a hundred times slower) is timed in alternating
    rounds with the others, so that their ratios hold on a busy machine.
    """
    from cbp.robot import RobotModel

    robot = RobotModel.load("franka_panda")
    q0 = robot.home()
    n, w = cfg.repetitions, cfg.warmup
    hand_step = HandWritten(robot).stepper(q0)
    base = "hand-written: pinocchio + numpy + daqp (no framework)"
    steps: list[Step] = [(base, hand_step, "")]
    steps += [
        (f"cbp Engine.step, solver={solver}", _engine_step(robot, solver), "")
        for solver in ("daqp", "piqp")
    ]
    steps += _peer_steps(robot, q0)
    timed = measure_interleaved([fn for _, fn, _ in steps], n, w)
    rows = [
        Row("reaching", case, median, p95, n, note=note)
        for (case, _, note), (median, p95) in zip(steps, timed, strict=True)
    ]
    reps = max(n // 20, 3)
    slow = _engine_step(robot, "cvxpy")
    rows.insert(
        3,
        Row(
            "reaching",
            "cbp Engine.step, solver=cvxpy",
            *measure(slow, reps, min(w, reps)),
            reps,
            note="timed on its own",
        ),
    )
    if not _installed("pink"):
        rows.append(Row("reaching", "pink: not installed (bench extra)", 0.0, 0.0, 0))
    if not _installed("mink", "mujoco"):
        rows.append(Row("reaching", "mink: not installed (bench extra)", 0.0, 0.0, 0))
    daqp = "cbp Engine.step, solver=daqp"
    for row in rows:
        if row.case != daqp and row.median_us > 0:
            relate(rows, row.case, daqp)
    relate(rows, daqp, base)
    return rows


def _engine_step(robot: Any, solver: str) -> Callable[[int], object]:
    """One engine step toward the cycling goals, from its own configuration."""
    engine, goal = _engine(robot, solver)
    current = {"q": robot.home()}

    def step(i: int) -> object:
        target = GOALS[(i // 64) % len(GOALS)]
        goal.set_target(target.translation, target.rotation)
        dq = engine.step(current["q"], DT).dq
        current["q"] = robot.integrate(current["q"], dq)
        return dq

    return step


def _installed(*modules: str) -> bool:
    """True when each of ``modules`` imports (peers are bench extras)."""
    try:
        for module in modules:
            importlib.import_module(module)
    except ImportError:
        return False
    return True


def _sibling(name: str) -> Any:
    """The module ``name`` of this folder, however this one was loaded.

    ``cbp bench`` loads this file by its path, the tests as
    ``benchmarks.bench``: the folder goes on ``sys.path`` for its siblings.
    """
    here = str(Path(__file__).resolve().parent)
    if here not in sys.path:
        sys.path.append(here)
    return importlib.import_module(name)


def _mink_steps(robot: Any, q0: np.ndarray) -> list[Step]:
    """The reaching step on mink (``benchmarks/mink_peer.py``), if installed.

    A reach of the first goal from ``q0`` on a model of its own checks first
    that mink's step gets there (within :data:`cbp.metrics.REACH_POSITION`
    and ``REACH_ROTATION``); the note says in how many steps.
    """
    if not _installed("mink", "mujoco"):
        return []
    peer = _sibling("mink_peer")
    steps = peer.MinkReach(robot, q0, GOALS, DT).reach(0, 500)
    if steps is None:
        raise RuntimeError("mink's reaching step did not reach GOALS[0] in 500 steps")
    return [
        (
            "mink.solve_ik + integrate (MuJoCo, daqp)",
            peer.MinkReach(robot, q0, GOALS, DT).stepper(64),
            "FrameTask, PostureTask, ConfigurationLimit, VelocityLimit as pink's; "
            f"reaches the first goal in {steps} steps",
        )
    ]


def _peer_steps(robot: Any, q0: np.ndarray) -> list[Step]:
    """The peers on the reaching task: pink and mink (if installed), placo."""
    steps: list[Step] = []
    if _installed("pink"):
        import pink
        from pink.limits import ConfigurationLimit, VelocityLimit
        from pink.tasks import FrameTask, PostureTask

        model = robot.model
        configuration = pink.Configuration(model, model.createData(), q0.copy())
        frame = FrameTask("panda_hand", position_cost=1.0, orientation_cost=0.3)
        posture = PostureTask(cost=1e-2)
        posture.set_target(0.5 * (robot.lower_limits + robot.upper_limits))
        limits = [ConfigurationLimit(model), VelocityLimit(model)]

        def pink_step(i: int) -> object:
            frame.set_target(GOALS[(i // 64) % len(GOALS)])
            v = pink.solve_ik(
                configuration, [frame, posture], DT, solver="daqp", limits=limits
            )
            configuration.integrate_inplace(v, DT)
            return v

        steps.append(
            (
                "pink.solve_ik + integrate (daqp)",
                pink_step,
                "FrameTask, PostureTask, ConfigurationLimit, VelocityLimit",
            )
        )
    steps += _mink_steps(robot, q0)
    import placo

    wrapper = placo.RobotWrapper(str(robot.urdf_path), placo.Flags.ignore_collisions)
    solver = placo.KinematicsSolver(wrapper)
    solver.mask_fbase(True)
    solver.enable_velocity_limits(True)
    solver.dt = DT
    for joint in ("panda_finger_joint1", "panda_finger_joint2"):
        solver.mask_dof(joint)
    for k, name in enumerate(robot.joint_names):
        wrapper.set_joint(name, float(q0[k]))
    wrapper.update_kinematics()
    task = solver.add_frame_task("panda_hand", GOALS[0].homogeneous)
    task.configure("hand", "soft", 1.0, 0.3)
    joints = solver.add_joints_task()
    joints.set_joints(
        {n: float(v) for n, v in zip(robot.joint_names, robot.middle(), strict=True)}
    )
    joints.configure("posture", "soft", 1e-2)

    def placo_step(i: int) -> object:
        task.T_world_frame = GOALS[(i // 64) % len(GOALS)].homogeneous
        solver.solve(True)
        wrapper.update_kinematics()
        return None

    steps.append(
        (
            "placo KinematicsSolver.solve + update_kinematics",
            placo_step,
            "frame task, joints task, joint and velocity limits (C++)",
        )
    )
    return steps


def _parts_rows(cfg: BenchConfig) -> list[Row]:
    """Where an engine step and a CAT step spend their time, part by part."""
    from cbp.robot import RobotModel
    from cbp.scenario import load_scenario

    n, w = cfg.repetitions, cfg.warmup
    robot = RobotModel.load("franka_panda")
    engine, goal = _engine(robot, "daqp")
    target = GOALS[1]
    q = robot.home()
    goal.set_target(target.translation, target.rotation)
    engine.step(q, DT)
    state, assembler, solver = engine.state, engine.assembler, engine.solver
    problem = assembler.assemble(state)
    entries = engine.entries
    total = "reaching step, fixed goal and configuration"
    parts: list[tuple[str, Callable[[int], object]]] = [
        (total, lambda i: engine.step(q, DT)),
        (
            "goal_pose.set_target (checked goal)",
            lambda i: goal.set_target(target.translation, target.rotation),
        ),
        ("kinematics (RobotState.update)", lambda i: state.update(q)),
        (
            "prepare, every entry",
            lambda i: [e.plugin.prepare(state, DT) for e in entries],
        ),
        (
            "assembly (linearize, stack, bounds, checks)",
            lambda i: assembler.assemble(state),
        ),
        ("of which goal_pose.linearize", lambda i: goal.linearize(state)),
        ("daqp solve", lambda i: solver.solve(problem)),
    ]
    boards: Any = load_scenario(SCENARIOS / "cat_boards.yaml")
    boards.q0[:] = _near_board(boards)
    world = boards.world_for_run()
    cat = boards.make_engine()
    _aim_at_final_goal(boards)
    near = boards.q0
    pair = (near, near + 1e-9)
    world.check(near)
    parts += [
        (
            "CAT: engine step with contact rows (contacts cached)",
            lambda i: cat.step(near, 0.02),
        ),
        (
            "CAT: contact query and validation (CollisionWorld.check)",
            lambda i: world.check(pair[i % 2]),
        ),
    ]
    parts += _octree_parts()
    # In alternating rounds: a slow spell of the machine falls on every part.
    timed = measure_interleaved([fn for _, fn in parts], n, w)
    rows = [
        Row("parts", case, median, p95, n)
        for (case, _), (median, p95) in zip(parts, timed, strict=True)
    ]
    for part, whole in SHARES:
        relate(rows, part, whole)
    return rows


#: (part, the whole it is a share of) among the "parts" rows, by case prefix.
SHARES = [
    ("goal_pose.set_target", "reaching step"),
    ("kinematics", "reaching step"),
    ("prepare", "reaching step"),
    ("assembly", "reaching step"),
    ("of which goal_pose.linearize", "assembly"),
    ("daqp solve", "reaching step"),
    ("octree: environment query", "octree: contact query"),
    ("octree: of which", "octree: environment query"),
    ("self pairs", "octree: contact query"),
]


def relate(rows: list[Row], part: str, whole: str) -> None:
    """Give the row whose case starts with ``part`` its ratio to ``whole``'s.

    Raises:
        KeyError: no row's case starts with one of them (a renamed row).
    """

    def find(prefix: str) -> Row:
        for row in rows:
            if row.case.startswith(prefix):
                return row
        raise KeyError(f"no benchmark row starts with {prefix!r}")

    of, to = find(part), find(whole)
    of.ratio_to, of.ratio = to.case, of.median_us / to.median_us


def _octree_parts() -> list[tuple[str, Callable[[int], object]]]:
    """The octree contact query inside the shelf, part by part."""
    from cbp.collision.shape_table import ShapeTable
    from cbp.state import RobotState

    world, q = _shelf_octree_world()
    world.check(q)
    env = world.environment
    robot = world.placed(RobotState(world.geometry.robot, q))
    shapes, placements = robot.shapes, robot.placements
    margin = world.margin(env)
    table = ShapeTable.for_shapes(shapes, margin + env.resolution)
    pair = (q, q + 1e-9)
    per_shape = world.settings.contacts_per_link
    return [
        (
            f"octree: contact query and validation ({len(env)} cells, "
            "CollisionWorld.check)",
            lambda i: world.check(pair[i % 2]),
        ),
        (
            "octree: environment query (compiled pass, reduction, refinement)",
            lambda i: env.query(robot, margin, per_shape),
        ),
        (
            "octree: of which the compiled pass over the cells near each shape",
            lambda i: table.candidates(env.index, placements, margin),
        ),
        (
            "self pairs (compiled narrow phase, CollisionWorld.self_contacts)",
            lambda i: world.self_contacts(robot),
        ),
    ]


# ---------------------------------------------------------------- 3-4: CAT steps


RESTART = 32
"""CAT step rows: steps from the start configuration before going back to it."""


def _final_goal(scenario: Any) -> pin.SE3:
    """The last pose of the scenario's goal stream."""
    stream = scenario.goal_stream()
    assert stream is not None, f"{scenario.spec.name} has no goal"
    return stream.pose(stream.end_time)


def _aim_at_final_goal(scenario: Any) -> None:
    """Give the scenario's goal task the stream's last pose."""
    goal = _final_goal(scenario)
    scenario.goal_task().set_target(goal.translation, goal.rotation)


def _cat_step(
    scenario: Any, capacity: int | None = None
) -> tuple[Callable[[int], object], Any]:
    """Validated CAT steps from a configuration near the obstacles, toward the goal.

    ``capacity`` replaces the contact constraint's row capacity (for scaling).
    """
    from cbp.engine import Engine
    from cbp.plugins.constraints.contact_normals_constraint import (
        ContactNormalsConstraint,
        ContactParams,
    )
    from cbp.qp import Entry

    world = scenario.world_for_run()
    entries = list(scenario.entries)
    if capacity is not None:
        for k, entry in enumerate(entries):
            if entry.plugin.type_name == "contact_normals":
                plugin = ContactNormalsConstraint(
                    ContactParams(max_contacts=capacity), scenario.robot, entry.name
                )
                plugin.attach_world(world)
                entries[k] = Entry.make(plugin, gain=entry.gain)
    engine = Engine(scenario.robot, entries, solver=scenario.spec.solver.name)
    _aim_at_final_goal(scenario)
    start = scenario.q0.copy()
    robot = scenario.robot
    current = {"q": start}

    def step(i: int) -> object:
        # As in the CAT loop: the check that validates a step finds the contacts
        # that constrain the next one. Every RESTART steps the arm goes back to
        # the start, so that it stays among the obstacles.
        q = start if i % RESTART == 0 else current["q"]
        dq = engine.step(q, 0.02).dq
        q_new = robot.integrate(q, dq)
        check = world.try_step(q_new)
        current["q"] = q_new if check.accepted else q
        return dq

    return step, world


def _cat_rows(cfg: BenchConfig) -> list[Row]:
    from cbp.collision import OccupancyEnvironment
    from cbp.scenario import load_scenario

    n, w = max(cfg.repetitions // 4, 3), min(cfg.warmup, 50)
    rows = []
    boards = load_scenario(SCENARIOS / "cat_boards.yaml")
    # Near the first board, where contacts are active.
    boards.q0[:] = _near_board(boards)
    step, world = _cat_step(boards)
    median, p95 = measure(step, n, w)
    contacts = len(world.check(boards.q0).contacts)
    rows.append(
        Row(
            "cat step",
            "boards, ground truth",
            median,
            p95,
            n,
            note=f"{contacts} contacts",
        )
    )
    shelf = load_scenario(SCENARIOS / "cat_shelf_reach.yaml")
    centres = _sample_objects(shelf, 0.01)
    env = OccupancyEnvironment(centres, 0.01, None)
    world = shelf.world_for_run()
    world.set_environment(env)
    step, _ = _cat_step(shelf)
    median, p95 = measure(step, max(n // 4, 3), min(w, 10))
    rows.append(
        Row(
            "cat step",
            f"shelf, octree ({len(centres)} cells)",
            median,
            p95,
            max(n // 4, 3),
        )
    )
    for row in rows:
        row.extra["steps_per_period"] = row.per_period
    return rows


def narrow_phase_rows(cfg: BenchConfig) -> list[Row]:
    """The compiled narrow phase against coal's, and the CAT step with each.

    In alternating rounds of one run: the hand-written reaching step, the CAT
    step on the boards (as in "cat step") with ``collision.narrow_phase``
    compiled and coal, and the CAT step's parts near the first board: the
    engine step with contact rows (contacts cached) and the contact query that
    validates a step, with either narrow phase; then the query alone inside
    the shelf (more pairs) with either. Public: ``benchmarks/narrow_phase.py``
    runs these rows alone.
    """
    from cbp.robot import RobotModel
    from cbp.scenario import load_scenario
    from cbp.state import RobotState

    n, w = max(cfg.repetitions // 2, 20), min(cfg.warmup, 50)
    robot = RobotModel.load("franka_panda")
    hand_step = HandWritten(robot).stepper(robot.home())
    base = "hand-written reaching step (as in reaching)"
    steps: list[tuple[str, Callable[[int], object]]] = [(base, hand_step)]
    checks: list[tuple[str, Callable[[int], object]]] = []
    queries: list[tuple[str, Callable[[int], object]]] = []
    contacts = {}
    for phase in ("compiled", "coal"):
        overrides = {"collision.narrow_phase": phase}
        boards: Any = load_scenario(SCENARIOS / "cat_boards.yaml", overrides=overrides)
        boards.q0[:] = _near_board(boards)
        step, _ = _cat_step(boards)
        steps.append((f"CAT step on the boards, {phase} narrow phase", step))
        # The parts on a scenario of their own: the CAT step keeps its world's
        # cache, carried contacts and GJK starts to itself.
        fixed: Any = load_scenario(SCENARIOS / "cat_boards.yaml", overrides=overrides)
        fixed.q0[:] = boards.q0
        world = fixed.world_for_run()
        near = fixed.q0
        pair = (near, near + 1e-9)
        contacts[phase] = len(world.check(near).contacts)
        checks.append(
            (
                f"CAT: contact query and validation, {phase} narrow phase "
                "(CollisionWorld.check)",
                lambda i, world=world, pair=pair: world.check(pair[i % 2]),
            )
        )
        if phase == "compiled":
            cat = fixed.make_engine()
            _aim_at_final_goal(fixed)
            world.check(near)
            checks.insert(
                0,
                (
                    "CAT: engine step with contact rows (contacts cached)",
                    lambda i, cat=cat, near=near: cat.step(near, 0.02),
                ),
            )
        shelf: Any = load_scenario(
            SCENARIOS / "cat_shelf_retreat.yaml", overrides=overrides
        )
        shelf_world = shelf.world_for_run()
        state = RobotState(shelf.robot, shelf.q0)
        queries.append(
            (
                f"full arm vs declared objects inside the shelf, {phase} narrow "
                "phase (CollisionWorld.query)",
                lambda i, world=shelf_world, state=state: world.query(state),
            )
        )
    parts = steps + checks + queries
    timed = measure_interleaved([fn for _, fn in parts], n, w)
    rows = [
        Row("narrow phase", case, median, p95, n)
        for (case, _), (median, p95) in zip(parts, timed, strict=True)
    ]
    for row in rows:
        if row.case.startswith("CAT step"):
            row.note = f"{contacts['compiled']} contacts at the start"
    compiled_step = "CAT step on the boards, compiled"
    relate(rows, compiled_step, base)
    relate(rows, "CAT step on the boards, coal", base)
    relate(rows, "CAT: engine step", compiled_step)
    relate(rows, "CAT: contact query and validation, compiled", compiled_step)
    relate(
        rows,
        "CAT: contact query and validation, coal",
        "CAT: contact query and validation, compiled",
    )
    relate(
        rows,
        "full arm vs declared objects inside the shelf, coal",
        "full arm vs declared objects inside the shelf, compiled",
    )
    return rows


def _shelf_octree_world() -> tuple[Any, np.ndarray]:
    """A collision world of the shelf scene's octree (1 cm), and a pose inside."""
    from cbp.collision import MetaballRefiner, OccupancyEnvironment
    from cbp.scenario import load_scenario

    shelf = load_scenario(SCENARIOS / "cat_shelf_retreat.yaml")  # starts inside
    world = shelf.world_for_run()
    cells = _sample_objects(shelf, 0.01)
    world.set_environment(OccupancyEnvironment(cells, 0.01, MetaballRefiner()))
    return world, shelf.q0


def _query_rows(cfg: BenchConfig) -> list[Row]:
    """The full-arm contact query alone: declared objects, and the map of them.

    Inside the shelf (the shelf retreat's start) the same configuration is
    queried against the declared objects and against a 1 cm map of their
    surfaces, with 450k more cells far away for the second map size; the
    boards row is the query of a scene with few contacts.
    """
    from cbp.collision import MetaballRefiner, OccupancyEnvironment
    from cbp.scenario import load_scenario

    n, w = max(cfg.repetitions // 2, 3), min(cfg.warmup, 50)
    boards = load_scenario(SCENARIOS / "cat_boards.yaml")
    octree_world, inside = _shelf_octree_world()
    centres = octree_world.environment.centres
    grown_world, _ = _shelf_octree_world()
    grown = np.concatenate([centres, _far_cells(9 * len(centres), 0.01)])
    grown_world.set_environment(OccupancyEnvironment(grown, 0.01, MetaballRefiner()))
    shelf = load_scenario(SCENARIOS / "cat_shelf_retreat.yaml")
    rows = []
    for case, world, q in (
        ("full arm vs declared objects (boards)", boards.world_for_run(), None),
        (
            "full arm vs declared objects inside the shelf",
            shelf.world_for_run(),
            inside,
        ),
        (
            f"full arm vs map inside the shelf: {len(centres)} cells, normals refined",
            octree_world,
            inside,
        ),
        (
            f"full arm vs larger map inside the shelf: {len(grown)} cells (far ones"
            " added), normals refined",
            grown_world,
            inside,
        ),
    ):
        q = _near_board(boards) if q is None else q
        # Two configurations 1 nrad apart, alternately: every check is a query.
        pair = (q, q + 1e-9)

        def query(i: int, world: Any = world, pair: Any = pair) -> object:
            return world.check(pair[i % 2])

        contacts = len(world.check(q).contacts)
        rows.append(
            Row(
                "query",
                case,
                *measure(query, n, w),
                n,
                note=f"{contacts} contacts (environment and self); kinematics included",
            )
        )
    return rows


def _run_query_rows(cfg: BenchConfig) -> list[Row]:
    """The full-arm query at the configurations of a CAT run through the shelf.

    CAT (virtual clock, declared objects) takes the arm out of the shelf; its
    recorded configurations are queried, in turns, against the declared
    objects, a 1 cm map of their surfaces (as in the rows above), and the map
    the head and side cameras build of the scene as the arm moves (unknown
    space counted as obstacle): the workload of CAT with cameras.
    """
    from cbp.collision import CollisionWorld, MetaballRefiner, OccupancyEnvironment
    from cbp.executors.cat import run_cat
    from cbp.perception.occupancy import OccupancyGrid
    from cbp.scenario import load_scenario
    from cbp.sim.camera import DepthCamera
    from cbp.sim.scene import PybulletScene
    from cbp.state import RobotState

    path = SCENARIOS / "cat_shelf_retreat.yaml"
    scenario = load_scenario(path, overrides={"method.cat.timing.clock": "virtual"})
    trace = run_cat(scenario)
    moved = np.r_[True, np.any(np.abs(np.diff(trace.q, axis=0)) > 1e-6, axis=1)]
    configurations = trace.q[moved]
    configurations = configurations[:: max(len(configurations) // 600, 1)]
    declared = scenario.world_for_run()
    # Worlds of the same robot geometry and settings, each with its obstacles.
    sampled = CollisionWorld(
        declared.geometry,
        OccupancyEnvironment(_sample_objects(scenario, 0.01), 0.01, MetaballRefiner()),
        declared.settings,
    )
    perceived = CollisionWorld(declared.geometry, None, declared.settings)
    spec = scenario.spec.perception
    grid = OccupancyGrid(spec, perceived.geometry)
    cameras = [c for c in spec.all_cameras if c.parent is None][:2]
    robot = scenario.robot
    with PybulletScene(robot, scenario.spec.world.objects, SCENARIOS) as scene:
        for k, q in enumerate(configurations[:: max(len(configurations) // 8, 1)]):
            scene.set_configuration(q)
            frame = DepthCamera(scene.client, cameras[k % 2]).capture()
            grid.integrate(frame, RobotState(robot, q))
    perceived.set_environment(grid.environment())
    worlds = (
        ("declared objects", declared),
        (f"1 cm map of their surfaces ({len(sampled.environment)} cells)", sampled),
        (
            f"perceived map, two cameras ({len(perceived.environment)} cells, "
            "unknown space blocked)",
            perceived,
        ),
    )
    n, w = max(cfg.repetitions // 2, 3), min(cfg.warmup, 50)
    count = len(configurations)

    def query(world: Any) -> Callable[[int], object]:
        return lambda i: world.check(configurations[i % count])

    timed = measure_interleaved([query(world) for _, world in worlds], n, w)
    rows = []
    for (name, world), (median, p95) in zip(worlds, timed, strict=True):
        contacts = np.mean([len(world.check(q).contacts) for q in configurations])
        rows.append(
            Row(
                "query",
                f"along a CAT run in the shelf: full arm vs {name}",
                median,
                p95,
                n,
                note=f"{count} configurations in turn; {contacts:.1f} contacts "
                "on average (environment and self)",
            )
        )
    relate(rows, rows[1].case, rows[0].case)
    relate(rows, rows[2].case, rows[0].case)
    return rows


def _near_board(scenario: Any) -> np.ndarray:
    """A configuration of the boards scene with the hand 2 cm above board 1."""
    from cbp.executors.ik_search import IkSearch
    from cbp.methods.settings import IkSearchSettings
    from cbp.run.budget import WallBudget

    search = IkSearch(scenario.robot, "panda_hand", None, IkSearchSettings())
    goal = pin.SE3(
        pin.rpy.rpyToMatrix(np.pi, 0.0, np.pi / 2), np.array([0.5, -0.24, 0.19])
    )
    q = search.solve(goal, scenario.q0, WallBudget(2.0))
    return scenario.q0 if q is None else q


def _sample_objects(scenario: Any, cell: float) -> np.ndarray:
    """Centres of the cells occupied by the scenario's objects' surfaces."""
    import trimesh

    points = []
    for obj in scenario.spec.world.objects:
        if obj.shape != "box":
            continue
        mesh = trimesh.creation.box(
            extents=obj.size, transform=obj.pose.to_se3().homogeneous
        )
        samples, _ = trimesh.sample.sample_surface_even(
            mesh, int(mesh.area / cell**2 * 4)
        )
        points.append(samples)
    cloud = np.concatenate(points)
    idx = np.unique(np.floor(cloud / cell).astype(int), axis=0)
    return np.asarray((idx + 0.5) * cell)


def _scaling_rows(cfg: BenchConfig) -> list[Row]:
    from cbp.collision.contacts import ContactSet
    from cbp.scenario import load_scenario
    from cbp.state import RobotState

    n, w = max(cfg.repetitions // 8, 3), min(cfg.warmup, 20)
    rows = []
    base = None
    for count in (0, 10, 50, 200):
        # The contact constraint's rows are sized by its capacity: one engine
        # per count, with room for exactly the rows it gets.
        scenario = load_scenario(SCENARIOS / "cat_boards.yaml")
        scenario.q0[:] = _near_board(scenario)
        probe = scenario.world_for_run()
        found = probe.contacts(RobotState(scenario.robot, scenario.q0))
        if len(found) == 0:
            break
        step, world = _cat_step(scenario, capacity=len(found) + count)
        pick = np.arange(count) % len(found)
        extra = found.select(pick) if count else ContactSet.empty()

        def with_rows(
            i: int, extra: Any = extra, world: Any = world, step: Any = step
        ) -> object:
            world.carry_over(extra)
            return step(i)

        median, p95 = measure(with_rows, n, w)
        row = Row(
            "scaling", f"CAT step, {len(found)} + {count} contact rows", median, p95, n
        )
        base = base or row
        row.ratio_to, row.ratio = base.case, median / base.median_us
        rows.append(row)
    return rows


def _far_cells(count: int, cell: float) -> np.ndarray:
    """``count`` occupied cells in a floor patch 3 m away from the robot."""
    side = int(np.ceil(np.sqrt(max(count, 1))))
    ix, iy = np.divmod(np.arange(count), side)
    return np.stack(
        [3.0 + (ix + 0.5) * cell, 3.0 + (iy + 0.5) * cell, np.full(count, 0.5 * cell)],
        axis=1,
    )


def _world_scaling_rows(cfg: BenchConfig) -> list[Row]:
    """The CAT step as the scene and the map grow far from the robot."""
    from cbp.collision import (
        EnvironmentObject,
        OccupancyEnvironment,
        PrimitiveEnvironment,
    )
    from cbp.scenario import load_scenario

    n, w = max(cfg.repetitions // 8, 3), min(cfg.warmup, 20)
    factors = (1, 10) if cfg.repetitions < 1000 else (1, 10, 100)
    rows: list[Row] = []
    boards = load_scenario(SCENARIOS / "cat_boards.yaml")
    boards.q0[:] = _near_board(boards)
    step, world = _cat_step(boards)
    objects = boards.environment_objects()
    base: Row | None = None
    for factor in factors:
        extra = [
            EnvironmentObject.primitive(
                f"far_{k}",
                "box",
                (0.1, 0.1, 0.1),
                pin.SE3(
                    np.eye(3), np.array([5.0 + 0.3 * (k % 30), 0.3 * (k // 30), 0.05])
                ),
            )
            for k in range(len(objects) * (factor - 1))
        ]
        world.set_environment(PrimitiveEnvironment(objects + extra))
        row = Row(
            "scaling",
            f"CAT step, boards + far objects: {len(objects) + len(extra)} objects",
            *measure(step, n, w),
            n,
        )
        base = base or row
        row.ratio_to, row.ratio = base.case, row.median_us / base.median_us
        rows.append(row)
    shelf = load_scenario(SCENARIOS / "cat_shelf_retreat.yaml")
    centres = _sample_objects(shelf, 0.01)
    step, world = _cat_step(shelf)
    base = None
    for factor in factors:
        cells = np.concatenate([centres, _far_cells(len(centres) * (factor - 1), 0.01)])
        world.set_environment(OccupancyEnvironment(cells, 0.01, None))
        reps = max(n // 4, 3)
        row = Row(
            "scaling",
            f"CAT step in the shelf, octree + far cells: {len(cells)} cells",
            *measure(step, reps, min(w, 5)),
            reps,
        )
        base = base or row
        row.ratio_to, row.ratio = base.case, row.median_us / base.median_us
        rows.append(row)
    return rows


# ---------------------------------------------------------------- 5: MP, orbit, map


def _mp_row(cfg: BenchConfig) -> list[Row]:
    import ompl.util as ou

    from cbp.executors.mp import MpPlanner
    from cbp.methods.settings import MpSettings
    from cbp.run import build_run
    from cbp.run.budget import WallBudget
    from cbp.scenario import load_scenario

    ou.RNG.setSeed(1)  # once, before any sampling: the runs differ, reproducibly
    scenario = load_scenario(SCENARIOS / "cat_shelf_reach.yaml")
    run = build_run(scenario, method="mp")
    samples = []
    solved = dropped = 0
    try:
        planner = MpPlanner(scenario, run, scenario.spec.method.settings(MpSettings))
        goal = _final_goal(scenario)  # in the shelf
        target = planner.search.solution_for(goal, scenario.q0, WallBudget(5))
        for _ in range(cfg.mp_seeds):
            start = time.perf_counter()
            plan = planner.plan(scenario.q0.copy(), goal, WallBudget(5.0), run)
            samples.append(time.perf_counter() - start)
            solved += plan.path is not None
            dropped += "touches between" in plan.note
        checks = planner.checks
        planner.close()
    finally:
        run.finish()
    times = np.array(samples) * 1e6
    return [
        Row(
            "planning",
            "MP: IK + RRT-Connect + simplify, shelf reach",
            float(np.median(times)),
            float(np.percentile(times, 95)),
            len(samples),
            note=(
                f"{solved} of {len(samples)} runs solved (5 s budget), {dropped} "
                "plans dropped as touching between the states OMPL checked (a run "
                "plans again); "
                f"{checks / max(len(samples), 1):.0f} of OMPL's validity checks per "
                "run, and the path's own checks along its segments; "
                f"IK goal found: {target is not None}"
            ),
        )
    ]


def _orbit_row(cfg: BenchConfig) -> list[Row]:
    from cbp.scenario import load_scenario

    scenario = load_scenario(SCENARIOS / "youbot_orbit_case1.yaml")
    engine = scenario.make_engine()
    inputs = scenario.inputs()
    robot = scenario.robot
    dt = 0.02
    # The run as the executor drives it: each tick from where the last one
    # went, with the last command as the velocity. (Repeating the start's tick
    # would time the first 0.06 s of the run, which the start errors make
    # infeasible and the engine eases with extra solves.)
    state = {"q": scenario.q0.copy(), "v": np.zeros(robot.nv)}
    eased = [0]

    def tick(i: int) -> object:
        for plugin, functions in inputs:
            plugin.set_input(np.array([f(dt * i) for f in functions]))
        dq, _, easing, _ = engine.step(state["q"], dt, state["v"])
        state["q"] = pin.integrate(robot.model, state["q"], dq)
        state["v"] = dq / dt
        eased[0] += easing is not None
        return dq

    n = cfg.repetitions
    warmup = max(cfg.warmup, 10)
    median, p95 = measure(tick, n, warmup)
    note_eased = f"; {eased[0]} ticks eased in all" if eased[0] else ""
    return [
        Row(
            "orbit",
            "one velocity-executor tick (youBot, 8 DOF)",
            median,
            p95,
            n,
            note=f"ticks of the running orbit ({n} after the first {warmup})"
            f"{note_eased}",
        )
    ]


def _map_row(cfg: BenchConfig) -> list[Row]:
    """Map updates: a frame into an empty map, and frames of a moving arm.

    The shelf reach scene seen by the head and side cameras (320x240) in turn,
    at eight configurations of an arm swinging around its start; each update
    integrates one frame (robot filtered out, seen space and the arm's space
    marked) and takes the snapshot the collision world queries.
    """
    from cbp.perception.occupancy import OccupancyGrid
    from cbp.scenario import load_scenario
    from cbp.sim.camera import DepthCamera
    from cbp.sim.scene import PybulletScene
    from cbp.state import RobotState

    scenario = load_scenario(SCENARIOS / "cat_shelf_reach.yaml")
    spec = scenario.spec.perception
    cameras = [c for c in spec.all_cameras if c.parent is None][:2]
    robot = scenario.robot
    swing = np.zeros(robot.nq)
    swing[:4] = (0.3, 0.2, 0.3, 0.2)
    states, frames = [], []
    with PybulletScene(robot, scenario.spec.world.objects, SCENARIOS) as scene:
        for k in range(8):
            q = np.clip(
                scenario.q0 + np.sin(2 * np.pi * k / 8) * swing,
                robot.lower_limits,
                robot.upper_limits,
            )
            scene.set_configuration(q)
            states.append(RobotState(robot, q))
            frames.append(DepthCamera(scene.client, cameras[k % 2]).capture())
    geometry = scenario.world_for_run().geometry
    n = max(cfg.repetitions // 40, 3)
    cold_n = min(n, 10)  # a grid of the scene's bounds each: ~7 MB
    empty = iter([OccupancyGrid(spec, geometry) for _ in range(cold_n + 1)])

    def first(i: int) -> object:
        grid = next(empty)  # a new one every call, the warm-up's included
        grid.integrate(frames[0], states[0])
        return grid.environment()

    grid = OccupancyGrid(spec, geometry)

    def update(i: int) -> object:
        grid.integrate(frames[i % 8], states[i % 8])
        return grid.environment()

    alone = measure(update, 4 * n, 16)
    # The same frames while a CAT loop runs in another thread, as in a run: the
    # map thread shares the GIL with it (the loop here never sleeps; a run's
    # sleeps a fifth of each period).
    boards = load_scenario(SCENARIOS / "cat_boards.yaml")
    boards.q0[:] = _near_board(boards)
    step, _ = _cat_step(boards)
    stop = threading.Event()

    def control() -> None:
        i = 0
        while not stop.is_set():
            step(i)
            i += 1

    loop = threading.Thread(target=control, name="bench-control", daemon=True)
    loop.start()
    try:
        beside = measure(update, 4 * n, 16)
    finally:
        stop.set()
        loop.join()
    size = f"{cameras[0].width}x{cameras[0].height}"
    cold = Row(
        "map",
        f"first {size} frame into an empty map: integrate + snapshot",
        *measure(first, cold_n, 1),
        cold_n,
    )
    moving = Row(
        "map",
        f"one {size} frame, two cameras in turn, arm moving: integrate + snapshot",
        *alone,
        4 * n,
        note=f"{len(grid.centres())} occupied cells, {len(grid.environment())} "
        "indexed (the obstacle shell); rendering excluded",
    )
    loaded = Row(
        "map",
        "the same frames while a CAT loop runs in another thread",
        *beside,
        4 * n,
        note="CAT steps on the boards without pause: the GIL shared",
    )
    loaded.ratio_to, loaded.ratio = moving.case, loaded.median_us / moving.median_us
    return [moving, loaded, cold]


# ---------------------------------------------------------------- runs in virtual time


def _run_seconds(cfg: BenchConfig, full: float, quick: float) -> float:
    """Simulated seconds of a run row: ``full``, ``quick``, or a moment (tests)."""
    if cfg.repetitions >= BenchConfig().repetitions:
        return full
    return quick if cfg.repetitions >= BenchConfig.quick().repetitions else 0.3


class _Stopwatch:
    """CPU time spent in chosen methods while a run goes (patched, then restored).

    Nested calls are counted once, in the outermost timed method of each
    name; a method timed under another counts in both.
    """

    def __init__(self, targets: dict[str, tuple[Any, str]]) -> None:
        self.seconds = dict.fromkeys(targets, 0.0)
        self._targets = targets
        self._saved: list[tuple[Any, str, Any]] = []

    def __enter__(self) -> _Stopwatch:
        for name, (owner, attr) in self._targets.items():
            original = getattr(owner, attr)
            self._saved.append((owner, attr, original))
            setattr(owner, attr, self._timed(name, original))
        return self

    def __exit__(self, *exc: object) -> None:
        for owner, attr, original in reversed(self._saved):
            setattr(owner, attr, original)

    def _timed(self, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        depth = [0]

        def timed(*args: Any, **kwargs: Any) -> Any:
            if depth[0]:
                return fn(*args, **kwargs)
            depth[0] += 1
            start = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[name] += time.process_time() - start
                depth[0] -= 1

        return timed


def _camera_overrides(renderer: str) -> dict[str, str]:
    """Overrides giving every camera of ``configs/cat.yaml`` the renderer named."""
    import yaml

    config = yaml.safe_load((SCENARIOS / "configs" / "cat.yaml").read_text())
    cameras = [c | {"renderer": renderer} for c in config["perception"]["cameras"]]
    return {
        "perception.cameras": yaml.safe_dump(cameras, default_flow_style=True),
        "perception.source": "depth_camera",
    }


def _virtual_run(
    path: Path,
    seconds: float,
    overrides: dict[str, str],
    watch: bool = False,
    parts: dict[str, tuple[Any, str]] | None = None,
) -> tuple[float, dict[str, float]]:
    """CPU seconds per simulated second of a CAT run on the virtual clock.

    The process's CPU time, not the wall clock's: on a machine shared with
    other work it is what the run would take on a core of its own (the run is
    one thread). Loading the scenario is excluded (building the run's parts,
    the cameras' first frames included, is not). With ``watch`` also the shares
    of that time spent rendering, mapping (of it, the snapshots), planning, in
    contact queries and in the simulation's steps, and in the methods
    ``parts`` names (name: (owner, method)).
    """
    from cbp.collision.world import CollisionWorld
    from cbp.executors.cat import CatPlanner, run_cat
    from cbp.perception.mapper import MapUpdater
    from cbp.perception.occupancy import OccupancyGrid
    from cbp.scenario import load_scenario
    from cbp.sim.camera import SimulatedCamera
    from cbp.sim.simulation import Simulation

    scenario = load_scenario(
        path,
        overrides={
            "method.cat.timing.clock": "virtual",
            "duration": repr(seconds),
            **overrides,
        },
    )
    targets = {
        "rendering": (SimulatedCamera, "capture"),
        "map integration": (MapUpdater, "submit"),
        "of it the snapshot": (OccupancyGrid, "environment"),
        "planning": (CatPlanner, "plan"),
        "contact queries": (CollisionWorld, "query"),
        "simulation": (Simulation, "step"),
        **(parts or {}),
    }
    with _Stopwatch(targets if watch else {}) as clock:
        start = time.process_time()
        trace = run_cat(scenario)
        cpu = time.process_time() - start
    shares = {k: v / cpu for k, v in clock.seconds.items()}
    return cpu / float(trace.t[-1]), shares


def _run_rows(cfg: BenchConfig) -> list[Row]:
    """Whole CAT runs on the virtual clock: CPU time per simulated second.

    The shelf reach with the five cameras of ``configs/cat.yaml`` (ray cast,
    and with PyBullet's tiny renderer as before) against the same scene with
    its declared objects; the boards (declared objects) against real time.
    The twin and the ray-cast camera run twice in turn (the lesser of each
    counts), the boards twice (the lesser) and once more timed for the
    account, the others once; the row's median is CPU microseconds per
    simulated second (:func:`_virtual_run`). Before them, one frame of each of the
    five cameras rendered both ways, in alternating rounds.
    """
    from cbp.engine import Engine
    from cbp.scenario import load_scenario
    from cbp.sim.camera import DepthCamera
    from cbp.sim.raycast import RayCaster
    from cbp.sim.scene import PybulletScene

    shelf = SCENARIOS / "cat_shelf_reach.yaml"
    scenario = load_scenario(shelf, overrides=_camera_overrides("raycast"))
    specs = scenario.spec.perception.all_cameras
    fixed = [c for c in specs if c.parent is None]
    tiny_specs = [replace(c, renderer="tiny") for c in fixed]
    with PybulletScene(scenario.robot, scenario.spec.world.objects, SCENARIOS) as scene:
        scene.set_configuration(scenario.q0)
        caster = RayCaster(scene.client)
        cast = [DepthCamera(scene.client, c, None, caster) for c in fixed]
        tiny = [DepthCamera(scene.client, c) for c in tiny_specs]
        n = max(cfg.repetitions // 40, 4)
        frames = measure_interleaved(
            [
                lambda i: cast[i % len(cast)].capture(),
                lambda i: tiny[i % len(tiny)].capture(),
            ],
            n,
            2,
            rounds=min(n, 10),
        )
    size = f"{fixed[0].width}x{fixed[0].height}"
    ray_row = Row(
        "runs", f"one {size} frame, ray cast (the shelf, 4 fixed cameras in turn)",
        *frames[0], n, note="depth noise included",
    )  # fmt: skip
    tiny_row = Row(
        "runs", f"one {size} frame, PyBullet's tiny renderer (the same)",
        *frames[1], n, ray_row.case, frames[1][0] / frames[0][0],
    )  # fmt: skip
    seconds = _run_seconds(cfg, 7.0, 3.0)
    # The first camera run of a process loads the map's kernels (twice as long).
    warm_up = [{}, _camera_overrides("raycast")] if seconds > 1.0 else []
    for overrides in warm_up:
        _virtual_run(shelf, 0.1, overrides)
    # The twin and the camera run in turn, twice: the lesser of each (a slow
    # spell of a shared machine raises CPU time too, by up to a fifth here).
    runs: dict[str, list[tuple[float, dict[str, float]]]] = {"twin": [], "cast": []}
    for _ in range(2):
        runs["twin"].append(_virtual_run(shelf, seconds, {}))
        cast_overrides = _camera_overrides("raycast")
        runs["cast"].append(_virtual_run(shelf, seconds, cast_overrides, True))
    twin, _ = min(runs["twin"], key=lambda run: run[0])
    cameras, shares = min(runs["cast"], key=lambda run: run[0])
    before, old = _virtual_run(shelf, seconds, _camera_overrides("tiny"), True)
    boards = _run_seconds(cfg, 10.0, 10.0)
    boards_path = SCENARIOS / "cat_boards.yaml"
    # The lesser of two runs; where the time goes from a third, timed (the
    # timers around ~50,000 calls add a few per cent).
    boards_cpu = min(_virtual_run(boards_path, boards, {})[0] for _ in range(2))
    _, boards_shares = _virtual_run(
        boards_path, boards, {}, True, {"of it the engine step": (Engine, "step")}
    )
    boards_order = (
        "planning",
        "of it the engine step",
        "contact queries",
        "simulation",
    )

    def account(parts: dict[str, float]) -> str:
        return "of the CPU time: " + ", ".join(
            f"{k} {100 * v:.0f} %" for k, v in parts.items()
        )

    twin_row = Row(
        "runs", "CAT in the shelf, declared objects, virtual clock: CPU per "
        "simulated second", twin * 1e6, twin * 1e6, 1,
        note=f"{seconds:g} s simulated; the lesser of two runs",
    )  # fmt: skip
    camera_row = Row(
        "runs", "CAT in the shelf, five cameras (ray cast), virtual clock: CPU "
        "per simulated second", cameras * 1e6, cameras * 1e6, 1, twin_row.case,
        cameras / twin, note=f"the lesser of two runs; {account(shares)}",
    )  # fmt: skip
    tiny_run = Row(
        "runs", "CAT in the shelf, five cameras (tiny renderer, as before), "
        "virtual clock: CPU per simulated second", before * 1e6, before * 1e6,
        1, twin_row.case, before / twin, note=account(old),
    )  # fmt: skip
    real = Row("runs", "real time: one simulated second", 1e6, 1e6, 1)
    boards_row = Row(
        "runs", "CAT on the boards, declared objects, virtual clock: CPU per "
        "simulated second", boards_cpu * 1e6, boards_cpu * 1e6, 1, real.case,
        boards_cpu, note=f"{boards:g} s simulated, the lesser of two runs: "
        f"{1 / boards_cpu:.2f}x real time on one core; a third run, "
        + account({k: boards_shares[k] for k in boards_order}),
    )  # fmt: skip
    return [ray_row, tiny_row, twin_row, camera_row, tiny_run, real, boards_row]


# ---------------------------------------------------------------- cameras per simulator


def _joint_setter(robot: Any, data: Any) -> Callable[[np.ndarray], None]:
    """Puts MuJoCo's robot (``data``) at a configuration, its joints by name."""
    model = robot.model
    names = [model.names[j] for j in range(1, model.njoints) if model.joints[j].nv == 1]

    def put(q: np.ndarray) -> None:
        for name, value in zip(names, q, strict=True):
            data.joint(name).qpos[0] = value

    return put


def frame_rows(cfg: BenchConfig) -> list[Row]:
    """One depth frame of the meshed Panda over the boards, four renderers.

    The boards scene (``scenarios/cat_boards.yaml``) with its first fixed
    camera (``overhead``, 320x240), its noise on; PyBullet's tiny renderer,
    the ray cast of PyBullet's shapes, MuJoCo's OpenGL renderer and the ray
    cast of MuJoCo's geoms, in alternating rounds, timed by the process's
    CPU time (its threads': MuJoCo's renderer draws in Mesa's): what a frame
    would cost on a core of its own, where wall time on a loaded machine
    counts the waits for a core (the tiny renderer's tripled here). The arm
    moves between frames (two configurations in turn): the ray casts draw
    what never moved once per camera and the arm every frame, as in a run.
    """
    if not _installed("mujoco"):
        return [Row("cameras", "MuJoCo: not installed (mujoco extra)", 0.0, 0.0, 0)]
    from cbp.scenario import load_scenario
    from cbp.sim.camera import DepthCamera, SimulatedCamera
    from cbp.sim.mujoco.camera import MujocoDepthCamera
    from cbp.sim.mujoco.physics import MujocoPhysics
    from cbp.sim.raycast import RayCaster
    from cbp.sim.scene import PybulletScene

    scenario = load_scenario(SCENARIOS / "cat_boards.yaml")
    robot, objects = scenario.robot, list(scenario.spec.world.objects)
    spec = next(c for c in scenario.spec.perception.all_cameras if c.parent is None)
    poses = [scenario.q0, scenario.q0 + 0.1]
    physics = MujocoPhysics(robot, objects, scenario.q0, scenario.spec.simulation)
    put = _joint_setter(robot, physics.data)
    model, data = physics.model, physics.data
    opengl = MujocoDepthCamera(model, data, replace(spec, renderer="opengl"))
    mujoco_cast = MujocoDepthCamera(model, data, replace(spec, renderer="raycast"))
    with PybulletScene(robot, objects, SCENARIOS) as scene:
        tiny = DepthCamera(scene.client, replace(spec, renderer="tiny"))
        cast = DepthCamera(
            scene.client,
            replace(spec, renderer="raycast"),
            None,
            RayCaster(scene.client),
        )

        def frames(
            camera: SimulatedCamera, pose: Callable[[np.ndarray], None]
        ) -> Callable[[int], object]:
            def frame(i: int) -> object:
                pose(poses[i % 2])
                return camera.capture()

            return frame

        n = max(cfg.repetitions // 40, 4)
        bullet = scene.set_configuration
        times = measure_interleaved(
            [
                frames(tiny, bullet),
                frames(cast, bullet),
                frames(opengl, put),
                frames(mujoco_cast, put),
            ],
            n,
            2,
            rounds=min(n, 10),
            clock=time.process_time,
        )
    opengl.close()
    size = f"{spec.width}x{spec.height}"
    what = f"one {size} frame of the Panda over the boards"
    tiny_row = Row(
        "cameras", f"{what}, PyBullet's tiny renderer", *times[0], n,
        note="CPU time; the overhead camera; noise included",
    )  # fmt: skip
    renderers = [
        "ray cast of PyBullet's shapes",
        "MuJoCo's OpenGL renderer (EGL, Mesa, no GPU)",
        "MuJoCo, ray cast of its geoms",
    ]
    rows = [tiny_row]
    for (median, p95), renderer in zip(times[1:], renderers, strict=True):
        ratio = median / times[0][0]
        case = f"{what}, {renderer}"
        rows.append(Row("cameras", case, median, p95, n, tiny_row.case, ratio))
    return rows


def mujoco_run_rows(cfg: BenchConfig) -> list[Row]:
    """CAT runs on MuJoCo, virtual clock: the cameras against the declared twin.

    The shelf reach with the five cameras of ``configs/cat.yaml`` and the
    boards with their own three, each against the same scene with its
    declared objects, all on MuJoCo (``simulator: mujoco``) with the ray cast;
    each pair twice in turn, the lesser of each counting
    (:func:`_virtual_run`). Then the shelf's cameras once with MuJoCo's
    OpenGL renderer.
    """
    if not _installed("mujoco"):
        return [Row("cameras", "MuJoCo: not installed (mujoco extra)", 0.0, 0.0, 0)]
    seconds = _run_seconds(cfg, 7.0, 3.0)
    mujoco = {"simulator": "mujoco"}
    shelf = SCENARIOS / "cat_shelf_reach.yaml"
    boards = SCENARIOS / "cat_boards.yaml"
    five = mujoco | _camera_overrides("raycast")
    own = mujoco | {"perception.source": "depth_camera"}
    if seconds > 1.0:  # the first camera run of a process loads the map's kernels
        _virtual_run(shelf, 0.1, five)
    rows: list[Row] = []
    for path, cameras, what in ((shelf, five, "five"), (boards, own, "its three")):
        runs: dict[str, list[tuple[float, dict[str, float]]]] = {"twin": [], "cams": []}
        for _ in range(2):
            runs["twin"].append(_virtual_run(path, seconds, mujoco))
            runs["cams"].append(_virtual_run(path, seconds, cameras, True))
        twin, _ = min(runs["twin"], key=lambda run: run[0])
        cams, shares = min(runs["cams"], key=lambda run: run[0])
        scene = path.stem.removeprefix("cat_").replace("_", " ")
        twin_row = Row(
            "cameras", f"MuJoCo: CAT {scene}, declared objects, virtual clock: CPU "
            "per simulated second", twin * 1e6, twin * 1e6, 1,
            note=f"{seconds:g} s simulated; the lesser of two runs",
        )  # fmt: skip
        account = ", ".join(f"{k} {100 * v:.0f} %" for k, v in shares.items())
        camera_row = Row(
            "cameras", f"MuJoCo: CAT {scene}, {what} cameras (ray cast), virtual "
            "clock: CPU per simulated second", cams * 1e6, cams * 1e6, 1,
            twin_row.case, cams / twin,
            note=f"the lesser of two runs; of the CPU time: {account}",
        )  # fmt: skip
        rows += [twin_row, camera_row]
        if path == shelf:
            gl = mujoco | _camera_overrides("opengl")
            cpu, parts = _virtual_run(path, seconds, gl, True)
            account = ", ".join(f"{k} {100 * v:.0f} %" for k, v in parts.items())
            case = (
                f"MuJoCo: CAT {scene}, five cameras (OpenGL), virtual clock: CPU "
                "per simulated second"
            )
            note = f"of the CPU time: {account}"
            ratio = cpu / twin
            rows.append(
                Row(
                    "cameras", case, cpu * 1e6, cpu * 1e6, 1, twin_row.case, ratio, note
                )
            )
    return rows


# ---------------------------------------------------------------- profile and output


def _profile_cat_step(cfg: BenchConfig) -> list[tuple[str, float]]:
    """The three largest costs of the CAT step on the boards, as % of its time.

    Sampled with pyinstrument (a bench extra); cProfile when it is missing.
    """
    from cbp.scenario import load_scenario

    scenario = load_scenario(SCENARIOS / "cat_boards.yaml")
    scenario.q0[:] = _near_board(scenario)
    step, _ = _cat_step(scenario)
    for i in range(20):
        step(i)
    n = max(cfg.repetitions // 3, 5)
    totals: dict[str, float] = {}
    try:
        from pyinstrument import Profiler
    except ImportError:
        profile = cProfile.Profile()
        profile.enable()
        for i in range(n):
            step(i)
        profile.disable()
        stats = pstats.Stats(profile, stream=io.StringIO())
        for (filename, line, func), values in stats.stats.items():  # type: ignore[attr-defined]
            where = Path(filename).name if filename != "~" else "builtin"
            totals[f"{func} ({where}:{line}, cProfile)"] = values[2]
    else:
        profiler = Profiler(interval=0.0005)
        profiler.start()
        for i in range(n):
            step(i)
        profiler.stop()
        session = profiler.last_session
        stack = [session.root_frame()] if session is not None else []
        while stack:
            frame = stack.pop()
            if frame is None:
                continue
            stack.extend(frame.children)
            # "[self]" and other synthetic frames hold their parent's own time.
            owner = frame.parent if frame.is_synthetic and frame.parent else frame
            own = frame.time - sum(child.time for child in frame.children)
            where = f"{Path(owner.file_path or '?').name}:{owner.line_no}"
            key = f"{owner.function} ({where})"
            totals[key] = totals.get(key, 0.0) + own
    total = sum(totals.values()) or 1.0
    top = sorted(totals.items(), key=lambda kv: kv[1], reverse=True)[:3]
    return [(name, 100.0 * seconds / total) for name, seconds in top]


def run_bench(
    cfg: BenchConfig, progress: Callable[[Row], None] | None = None
) -> dict[str, Any]:
    """Run every row; return rows, profile and the machine's description."""
    load = os.getloadavg()[0]
    rows: list[Row] = []
    for group in (
        _reaching_rows,
        _parts_rows,
        _cat_rows,
        narrow_phase_rows,
        _query_rows,
        _run_query_rows,
        _scaling_rows,
        _world_scaling_rows,
        _mp_row,
        _orbit_row,
        _map_row,
        _run_rows,
        frame_rows,
        mujoco_run_rows,
    ):
        for row in group(cfg):
            rows.append(row)
            if progress is not None:
                progress(row)
    profile = _profile_cat_step(cfg)
    load_at_end = os.getloadavg()[0]
    return {
        "machine": _machine()
        | {"load": f"{load:.1f} at the start, {load_at_end:.1f} at the end"},
        "rows": [asdict(r) | {"per_period": r.per_period} for r in rows],
        "profile_cat_step": profile,
    }


def _machine() -> dict[str, str]:
    out = {"python": platform.python_version(), "machine": platform.machine()}
    for dist in (
        "pin",
        "numpy",
        "daqp",
        "piqp",
        "cvxpy",
        "coal",
        "ompl",
        "placo",
        "pin-pink",
        "mink",
        "mujoco",
    ):
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            out[dist] = "not installed"
    return out


def format_row(row: Row) -> str:
    """One line for the terminal."""
    ratio = f"  {row.ratio:.2f}x {row.ratio_to}" if row.ratio is not None else ""
    return (
        f"[{row.group}] {row.case}: {row.median_us:.1f} us (p95 {row.p95_us:.1f}), "
        f"{row.per_period:.0f} per 33 ms{ratio}"
    )


def write_results(result: dict[str, Any], path: Path, command: str) -> None:
    """Write benchmarks/RESULTS.md (or ``path``) from a run's result."""
    m = result["machine"]
    versions = ", ".join(
        f"{k} {v}" for k, v in m.items() if k not in ("python", "machine", "load")
    )
    load = f", load average (1 min) {m['load']}" if "load" in m else ""
    lines = [
        "# Benchmarks",
        "",
        f"Generated by `{command}`. Every row ran in one process, one after the",
        "other: only ratios between rows of one run are meaningful.",
        f"Machine: {m['machine']}, Python {m['python']}{load}; {versions}.",
        "",
    ]
    groups: dict[str, list[dict[str, Any]]] = {}
    for row in result["rows"]:
        groups.setdefault(row["group"], []).append(row)
    for group, rows in groups.items():
        lines += [
            f"## {group}",
            "",
            "| case | median us | p95 us | per 33 ms | ratio | n | note |",
            "|---|---:|---:|---:|---|---:|---|",
        ]
        for r in rows:
            ratio = (
                f"{r['ratio']:.2f}x {r['ratio_to']}" if r["ratio"] is not None else ""
            )
            lines.append(
                f"| {r['case']} | {r['median_us']:.1f} | {r['p95_us']:.1f} | "
                f"{r['per_period']:.0f} | {ratio} | {r['n']} | {r['note']} |"
            )
        lines.append("")
    lines += targets_table(result["rows"])
    lines += _where_the_time_goes(result["rows"])
    lines += ["## Profile of the CAT step (boards): largest own-time shares", ""]
    lines += [f"1. {name}: {pct:.0f} %" for name, pct in result["profile_cat_step"]]
    lines.append("")
    # The other scripts' sections (collision.py, sweep.py, ...) stay.
    keep = _sibling("results_file").keep_other_sections
    path.write_text(keep(path, "\n".join(lines)))


def _where_the_time_goes(rows: list[dict[str, Any]]) -> list[str]:
    """The missed targets' time, from the ``parts`` rows of the same run."""
    part = {r["case"]: r["median_us"] for r in rows if r["group"] == "parts"}
    hand = next((r for r in rows if r["case"].startswith("hand-written")), None)
    if not part or hand is None:
        return []

    def us(prefix: str) -> float:
        return float(next(v for k, v in part.items() if k.startswith(prefix)))

    total = us("reaching step")
    assembly = us("assembly")
    mp = next(
        (r["median_us"] for r in rows if r["case"].startswith("MP: IK")),
        float("nan"),
    )
    declared = next(
        (
            r["median_us"]
            for r in rows
            if r["case"].endswith("objects inside the shelf")
        ),
        float("nan"),
    )
    orbit = next((r["median_us"] for r in rows if r["group"] == "orbit"), float("nan"))
    listed = us("kinematics") + us("prepare") + assembly + us("daqp")
    return [
        "## Where the time goes",
        "",
        f"- `Engine.step` of the reaching task at a fixed configuration: "
        f"{total:.0f} us. Kinematics {us('kinematics'):.1f}, prepare "
        f"{us('prepare'):.1f}, assembly {assembly:.1f} (the goal's linearization "
        f"{us('of which'):.1f} of it, one compiled call for the pose error and "
        "its Jacobian; the rest is one call per entry writing into the stacked "
        "buffers, the goal's step limit (one compiled call, in place), the "
        "bounds, and one compiled pass that forms H, g and the bounds and "
        "checks them for NaN), daqp "
        f"{us('daqp'):.1f}; {total - listed:.1f} between them (the checks of q "
        "and dt, the solver's trial context, made once, the step guard's one "
        "compiled call, the result; 7.9 us when the trial context was a "
        "generator made every step). The reaching row "
        f"also checks each new goal ({us('goal_pose.set_target'):.1f} us) and "
        f"integrates. The hand-written step ({hand['median_us']:.0f} us) does the "
        "same kinematics, linearization and daqp call in plain numpy, with the "
        "two limits merged into variable bounds and nothing checked.",
        f"- CAT step on the boards: the engine step with contact rows "
        f"{us('CAT: engine'):.0f} us, the contact query that validates the step "
        f"(and gives the next one its contacts) {us('CAT: contact'):.0f} us. The "
        "query is one compiled call: the shapes' placements from the joints, "
        "the broad phase (bounding spheres and boxes), and GJK (EPA where they "
        "overlap) on the obstacle and self pairs it keeps, each pair starting "
        "from its last normal (`cbp.collision.convex_kernels`; "
        "`collision.narrow_phase: coal` calls coal from Python per pair, as "
        "before: the narrow phase rows); the engine's cost over the reaching "
        "step is the two contact constraints (latching their contacts, their "
        "rows in one compiled pass from the joints' world Jacobians) and a QP "
        "with their rows.",
        f"- Orbit tick (youBot, `youbot_orbit_case1`, 20 ms ticks): {orbit:.0f} "
        "us. By parts (medians of 3000 ticks, measured once at load 7): the "
        "assembly about 50 us (eight entries' linearizations: the view "
        "direction's rows one compiled call, the other orbit rows a few numpy "
        "calls each, the planar base's joint-space rows through pinocchio), "
        "the coasting drift and its refinement about 35 us (kinematics a step "
        "ahead and the five drifting rows' values there; their arithmetic is "
        "three compiled passes), daqp about 12 us, prepare about 9 us "
        "(joint_acceleration's bounds one compiled pass), the operator's "
        "inputs about 10 us, the checks, kinematics and step guard about "
        "11 us. Before these passes the same measurement gave 297 us: assembly "
        "112, drift and refinement 102 (a dozen numpy calls per drifting "
        "plugin on fancy-indexed rows), prepare 26.",
        f"- Octree query inside the shelf: {us('octree: contact'):.0f} us in all. "
        f"The environment query {us('octree: environment'):.0f} us, of which the "
        f"compiled pass over the cells in each shape's box "
        f"{us('octree: of which'):.0f} us (the rest: reducing candidates to a "
        "few per shape, refining their normals, and the arrays around them); "
        f"the self pairs {us('self pairs'):.0f} us; kinematics, shape placements "
        "and stacking the contacts the rest. The same configuration against the "
        f"declared objects costs {declared:.0f} us in all and gives 7 contacts "
        "to the map's 17. In the compiled pass (counted once, not timed per "
        "run): about 4 us is the call with named tuples (about 1.5 us in the "
        "query, which passes its arguments flat, packed once per map and "
        "settings, and gets the contacts back in two arrays), "
        "about 6 us visiting the ~1,100 non-empty bricks in the columns around "
        "the 11 shapes' boxes (each column's non-empty bricks are bits: the "
        "~6,700 empty bricks there are not read) and keeping the ~320 that "
        "reach a box along its axes, about 9 us testing those bricks' places "
        "against the box, 64 at once in one vectorised loop from the brick's "
        "corner (a brick of 4 x 4 x 4 cells keeps its occupied places as bits, "
        "its cells in place order: no centre is read, ~6,700 occupied places, "
        "~1,800 inside), and about 10 us measuring the ~1,800 inside a box: "
        "most against the faces of the eight face-grid points around them, "
        "those beyond 2 cm against their nearest point's face only (a lower "
        "bound; about half are rejected by the grid's lower bound alone). "
        "The grid indices are not clamped (a cell in a shape's grown box is a "
        "step inside its grid; clamping took 1.6 us). Rotating each cell of "
        "those bricks into the shape's frame, one by one as before, took about "
        "20 us (this row was 42 us then). "
        "Tried and not kept: the places' grid coordinates precomputed per "
        "shape (no faster than the unclamped lookup), the measurement without "
        "the lower bound's branch (slower: loading the far cells' faces and "
        "planes costs more than the mispredicted branch), "
        "the places tested in single precision (eight per "
        "instruction: no faster), the box narrowed by four diagonal slabs "
        "(slower in the vectorised loop; 1 us faster per cell, but it drops "
        "far cells the lower bound keeps), a branch-free pass dropping the "
        "cells the face grid shows far (slower), face and value grids in one "
        "array (no faster), candidate buffers allocated once (no faster); "
        "before these, lists of the cells near each shape reused while it "
        "moves less than 1 cm (faster at this configuration, slower along a "
        "CAT run), skipping bricks by a lower bound of their distance, and "
        "branch-free compaction of the cells in a box. A distance field of the "
        "map does not replace the pass for exact hull distances: sampling the "
        "hulls' surfaces at 1 cm takes ~5,500 lookups per query, more than the "
        "cells measured; spheres against a field (as CHOMP and cuRobo do) "
        "would be faster but over-approximate the links.",
        f"- MP plan in the shelf: {mp / 1e3:.0f} ms (median). About 6 ms of it "
        "checks the final path all along its segments (12 ms without, measured "
        "once): configurations a sweep bound apart (`cbp.collision.motion`: at "
        "most the 1 cm padding, so the unpadded links keep half of it), about "
        "one per cm the links sweep. The bound adds up each joint's motion times "
        "the reach of what it carries, so it overestimates motions in which "
        "joints turn against each other (a CAT step's bound was up to 77 mm "
        "where no point moved 10 mm); a plan's joints mostly move one way.",
        "- Map update (per frame of the five cameras of a CAT run in the "
        "shelf, virtual clock): the see-through pass over the grid's unknown "
        "and occupied cells in the frustum about 2.3 ms, after the image's "
        "ranges eroded over 3x3 pixels (0.6 ms); one pass that turns the depth "
        "image into points, drops those within robot_margin of the robot "
        "(tested against the planes of the shapes whose sphere they are in) "
        "and marks the rest's cells 2.5 ms; carving the robot's space 0.3 ms; "
        "the snapshot 1.1 ms (only bricks that changed are rescanned; the "
        "first frame's snapshot rescans all). Beside a control loop in another "
        "thread a frame costs 1.2-1.3x as much; before these passes were "
        "compiled whole it cost 6x (72 against 12 ms), each numpy call giving "
        "up the GIL and waiting up to the 5 ms switch interval for it.",
        "",
    ]


#: Targets as ratios to a baseline of the same run: (row group, case prefix,
#: baseline group, baseline case prefix, largest ratio, what it is). Absolute
#: times on shared machines vary by 2x between runs; ratios within a run hold.
#: The ratios to the hand-written step (pinocchio + numpy + daqp, no framework:
#: a unit of this machine's speed) are the absolute targets the issues set,
#: divided by that step's 25.8 us in the run they were set against.
#: A limit of None: the ratio is reported, not judged.
TARGETS: list[tuple[str, str, str, str, float | None, str]] = [
    (
        "reaching",
        "cbp Engine.step, solver=daqp",
        "reaching",
        "hand-written",
        1.10,
        "engine step / hand-written step (issue 40)",
    ),
    (
        "reaching",
        "cbp Engine.step, solver=daqp",
        "reaching",
        "pink",
        1 / 4,
        "engine step / pink's (issue 40)",
    ),
    (
        "reaching",
        "cbp Engine.step, solver=daqp",
        "reaching",
        "placo",
        None,
        "engine step / placo's (C++; issue 40's moonshot: 3)",
    ),
    (
        "reaching",
        "cbp Engine.step, solver=daqp",
        "reaching",
        "mink",
        None,
        "engine step / mink's (MuJoCo; issue 53)",
    ),
    (
        "query",
        "full arm vs map inside the shelf",
        "query",
        "full arm vs declared objects inside the shelf",
        1.2,
        "contact query against the map / against the declared objects, inside the "
        "shelf (issue 16)",
    ),
    (
        "query",
        "along a CAT run in the shelf: full arm vs 1 cm map",
        "query",
        "along a CAT run in the shelf: full arm vs declared",
        1.2,
        "the same, at the configurations of a CAT run through the shelf",
    ),
    (
        "query",
        "full arm vs larger map",
        "query",
        "full arm vs map inside the shelf",
        1.1,
        "contact query against the map at ~500k cells / at ~50k (issue 16: flat)",
    ),
    (
        "cat step",
        "boards",
        "reaching",
        "hand-written",
        130.0 / 25.8,
        "CAT step with contacts / hand-written step (130 us: 250 per period)",
    ),
    (
        "narrow phase",
        "CAT step on the boards, compiled",
        "narrow phase",
        "hand-written",
        3.5,
        "CAT step with contacts, compiled narrow phase / hand-written step, "
        "interleaved (issue 40; moonshot 2.5)",
    ),
    (
        "narrow phase",
        "CAT: contact query and validation, compiled",
        "narrow phase",
        "CAT: contact query and validation, coal",
        1.0,
        "CAT step's contact query, compiled narrow phase / coal's",
    ),
    (
        "planning",
        "MP",
        "reaching",
        "hand-written",
        25_000.0 / 25.8,
        "MP plan in the shelf / hand-written step (25 ms)",
    ),
    (
        "orbit",
        "one",
        "reaching",
        "hand-written",
        200.0 / 25.8,
        "orbit tick / hand-written step (200 us)",
    ),
    (
        "map",
        "one",
        "reaching",
        "hand-written",
        15_000.0 / 25.8,
        "map update per frame / hand-written step (15 ms, issue 16)",
    ),
    (
        "map",
        "the same frames while a CAT loop",
        "map",
        "one",
        1.5,
        "map update beside a busy control loop / alone (the map thread must not "
        "wait for the GIL)",
    ),
    (
        "runs",
        "CAT in the shelf, five cameras (ray cast)",
        "runs",
        "CAT in the shelf, declared objects",
        1.3,
        "a CAT run with the five cameras / its declared-object twin, virtual clock",
    ),
    (
        "cameras",
        "one 320x240 frame of the Panda over the boards, MuJoCo, ray cast",
        "cameras",
        "one 320x240 frame of the Panda over the boards, PyBullet's tiny",
        1 / 5,
        "a MuJoCo depth frame of the Panda over the boards (ray cast, the "
        "default) / the tiny renderer's, CPU time (issue 53)",
    ),
    (
        "cameras",
        "one 320x240 frame of the Panda over the boards, MuJoCo's OpenGL",
        "cameras",
        "one 320x240 frame of the Panda over the boards, PyBullet's tiny",
        1 / 5,
        "the same with MuJoCo's OpenGL renderer (renderer: opengl)",
    ),
    (
        "cameras",
        "MuJoCo: CAT shelf reach, five cameras",
        "cameras",
        "MuJoCo: CAT shelf reach, declared objects",
        1.5,
        "a CAT run with the five cameras on MuJoCo / its declared twin on MuJoCo, "
        "virtual clock (issue 53)",
    ),
    (
        "cameras",
        "MuJoCo: CAT boards, its three cameras",
        "cameras",
        "MuJoCo: CAT boards, declared objects",
        1.5,
        "the boards with their three cameras on MuJoCo / the declared twin on "
        "MuJoCo, virtual clock (issue 53)",
    ),
    (
        "runs",
        "CAT on the boards",
        "runs",
        "real time",
        0.2,
        "a CAT run of the boards on the virtual clock, CPU / simulated time (5x "
        "real time on one core)",
    ),
]


def targets_table(rows: list[dict[str, Any]]) -> list[str]:
    """The targets as a Markdown table: met, or missed by how much.

    ``rows`` as in a run's result (dicts of :class:`Row`'s fields). A target
    whose rows are not in ``rows`` (a renamed or skipped row) is listed as not
    measured. Printed at the end of ``cbp bench`` and written to RESULTS.md.
    """

    def find(group: str, prefix: str) -> dict[str, Any] | None:
        return next(
            (
                r
                for r in rows
                if r["group"] == group
                and r["case"].startswith(prefix)
                and r["median_us"] > 0
            ),
            None,
        )

    lines = [
        "## Targets",
        "",
        "Each target is a ratio to a row of the same run.",
        "",
        "| target | measured | verdict |",
        "|---|---:|---|",
    ]
    for group, prefix, base_group, base_prefix, limit, what in TARGETS:
        row, base = find(group, prefix), find(base_group, base_prefix)
        target = what if limit is None else f"{what} <= {limit:.3g}"
        if row is None or base is None:
            lines.append(f"| {target} | | not measured |")
            continue
        ratio = row["median_us"] / base["median_us"]
        if limit is None:
            verdict = "reported"
        else:
            verdict = "met" if ratio <= limit else f"missed by {ratio / limit:.2f}x"
        lines.append(f"| {target} | {ratio:.3g} | {verdict} |")
    return [*lines, ""]


def dump(result: dict[str, Any], path: Path) -> None:
    """Write the result as JSON."""
    path.write_text(json.dumps(result, indent=2) + "\n")
