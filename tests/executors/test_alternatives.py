"""The IK, MP and JT methods and cbp compare (fast cases)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from cbp.collision import CollisionWorld, PrimitiveEnvironment, RobotGeometry
from cbp.executors.ik import interpolate_checked
from cbp.executors.ik_search import IkSearch
from cbp.executors.jt import run_jt
from cbp.executors.mp import MpPlanner, RrtConnect
from cbp.methods.settings import IkSearchSettings, PlannerSettings
from cbp.metrics import run_metrics
from cbp.run import build_run
from cbp.run.budget import WallBudget
from cbp.scenario import Scenario, load_scenario
from tests.collision.test_motion import plate_across_the_hand
from tests.conftest import VIRTUAL_CLOCK, run_cbp

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
DOWN = np.diag([1.0, -1.0, -1.0])


@pytest.fixture(scope="module")
def boards() -> Scenario:
    return load_scenario(SCENARIOS / "cat_boards.yaml")


def _search(scenario: Scenario) -> IkSearch:
    return IkSearch(
        scenario.robot, "panda_hand", scenario.world_for_run(), IkSearchSettings()
    )


def test_ik_search_finds_a_near_collision_free_solution(boards: Scenario) -> None:
    search = _search(boards)
    goal = pin.SE3(
        pin.rpy.rpyToMatrix(np.pi, 0, np.pi / 2), np.array([0.5, -0.35, 0.2])
    )
    q = search.solve(goal, boards.q0, WallBudget(1.0))
    assert q is not None
    data = boards.robot.model.createData()
    pin.framesForwardKinematics(boards.robot.model, data, q)
    M = data.oMf[search.frame_id]
    assert np.linalg.norm(M.translation - goal.translation) < 2e-3
    assert search.collision_free(q)
    assert np.max(np.abs(q - boards.q0)) < 0.5  # near the start, not another branch


def test_ik_search_refuses_unreachable_and_colliding_goals(boards: Scenario) -> None:
    search = _search(boards)
    far = pin.SE3(DOWN, np.array([1.5, 0.0, 0.3]))
    assert search.solve(far, boards.q0, WallBudget(2.0)) is None
    # The hand inside the middle board.
    inside = pin.SE3(
        pin.rpy.rpyToMatrix(np.pi, 0, np.pi / 2), np.array([0.5, 0.0, 0.12])
    )
    assert search.solve(inside, boards.q0, WallBudget(2.0)) is None


def test_interpolation_stops_before_a_collision(boards: Scenario) -> None:
    """Straight across the first board in joint space: the path ends before it."""
    search = _search(boards)
    beyond = pin.SE3(
        pin.rpy.rpyToMatrix(np.pi, 0, np.pi / 2), np.array([0.5, -0.12, 0.15])
    )
    target = search.solve(beyond, boards.q0, WallBudget(2.0))
    assert target is not None
    plan = interpolate_checked(boards.q0, target, 0.02, search, WallBudget(1.0))
    assert plan.path is not None
    assert plan.note.startswith("collision ahead")
    assert all(search.collision_free(q) for q in plan.path)
    assert np.max(np.abs(plan.path[-1] - target)) > 0.02


def _plan_over_the_board(boards: Scenario, simplify: str = "shortcut"):
    """One MP plan from the boards' start to the far side of the first board.

    Returns the plan, the planner (closed) and the run (finished).
    """
    run = build_run(boards, method="mp")
    try:
        settings = dataclasses.replace(boards.spec.method.mp, simplify=simplify)
        planner = MpPlanner(boards, run, settings)
        goal = pin.SE3(
            pin.rpy.rpyToMatrix(np.pi, 0, np.pi / 2), np.array([0.5, -0.12, 0.15])
        )
        plan = planner.plan(boards.q0.copy(), goal, WallBudget(2.0), run)
        planner.close()
    finally:
        run.finish()
    return plan, planner, run


@pytest.mark.parametrize("simplify", ["shortcut", "full"])
def test_mp_plans_over_the_board(boards: Scenario, simplify: str) -> None:
    """RRT-Connect + simplification: a valid path to the far side of a board."""
    plan, planner, _ = _plan_over_the_board(boards, simplify)
    assert plan.path is not None, plan.note
    np.testing.assert_allclose(plan.path[0], boards.q0)
    assert np.max(np.abs(np.diff(plan.path, axis=0))) <= 0.05 + 1e-9  # waypoints
    # Free at every waypoint and all along the segments between them.
    search = planner.search
    assert all(search.collision_free(q) for q in plan.path)
    assert search.path_free(plan.path)


def test_mp_plans_again_in_the_period_when_a_plan_touches(
    boards: Scenario, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A plan dropped by the sweep check (injected) is replaced in the same call.

    From new trees: the trees that found it would give the same path again.
    """
    from cbp.executors.ik_search import IkSearch

    path_free, begin = IkSearch.path_free, RrtConnect.begin
    checks, begun = [0], [0]

    def touching_first(self, points, budget=None):  # type: ignore[no-untyped-def]
        checks[0] += 1  # the first plan's shortened path and its path as found
        return checks[0] > 2 and path_free(self, points, budget)

    def counted(self, q, target):  # type: ignore[no-untyped-def]
        begun[0] += 1
        begin(self, q, target)

    monkeypatch.setattr(IkSearch, "path_free", touching_first)
    monkeypatch.setattr(RrtConnect, "begin", counted)
    plan, _, run = _plan_over_the_board(boards)
    assert checks[0] >= 3
    assert begun[0] == 2  # the second plan grew new trees
    assert plan.path is not None, plan.note
    events = "\n".join(msg for _, msg in run.log.events)
    assert "touches between the states OMPL checked; planning again" in events


def _across_a_plate(robot) -> tuple[np.ndarray, np.ndarray, CollisionWorld]:
    """The shoulder turning 1.2 rad, free at both ends, across a 3 mm plate."""
    a = robot.home()
    b = a.copy()
    b[0] += 1.2
    plate = plate_across_the_hand(robot, a, b)
    world = CollisionWorld(RobotGeometry(robot), PrimitiveEnvironment([plate]))
    assert world.is_free(a)
    assert world.is_free(b)
    return a, b, world


def test_a_plan_that_touches_between_the_states_ompl_checked_is_dropped(
    robots,
) -> None:
    """A plan straight through a plate OMPL's coarse motion checks missed.

    It is refused (it used to be kept, as OMPL's own states).
    """
    robot = robots["panda"]
    a, b, world = _across_a_plate(robot)
    settings = PlannerSettings(check_resolution=0.5)  # the ends only
    search = IkSearch(robot, "panda_hand", world, settings.search)
    rrt = RrtConnect(robot, search, settings, seeded=True)
    try:
        rrt.begin(a, b)
        assert rrt.grow(WallBudget(2.0), 1.0)
        points, note = rrt.path(WallBudget(1.0))
    finally:
        rrt.close()
    assert points is None
    assert "touches between" in note


def test_an_ik_solve_that_stalls_is_given_up_early(robots) -> None:
    """Out of reach, a solve stops once its error stops falling; within reach it solves."""
    robot = robots["panda"]
    search = IkSearch(robot, "panda_hand", None, IkSearchSettings())
    budget = WallBudget(10.0)
    far = pin.SE3(np.eye(3), np.array([2.0, 0.0, 0.5]))  # 2 m away: out of reach
    before = search.solves
    assert search._solve_from(far, robot.home(), None, budget) is None
    stalled = search.solves - before
    assert IkSearchSettings().stall_iterations < stalled < 80
    never = IkSearch(robot, "panda_hand", None, IkSearchSettings(stall_iterations=0))
    assert never._solve_from(far, robot.home(), None, budget) is None
    assert never.solves == 80  # every iteration, as before
    data = robot.model.createData()
    q = robot.home() + 0.3
    pin.framesForwardKinematics(robot.model, data, q)
    near = data.oMf[search.frame_id].copy()
    assert search._solve_from(near, robot.home(), None, budget) is not None


def test_rrt_connect_keeps_its_trees_for_the_same_start_and_target(robots) -> None:
    """Begun for a start and a target, the trees are grown on for them until a path is taken."""
    robot = robots["panda"]
    a, b, world = _across_a_plate(robot)
    settings = PlannerSettings()
    search = IkSearch(robot, "panda_hand", world, settings.search)
    rrt = RrtConnect(robot, search, settings, seeded=True)
    try:
        assert not rrt.continues(a, b)  # nothing begun
        rrt.begin(a, b)
        assert rrt.continues(a, b)
        assert not rrt.continues(a + 1e-3, b)
        assert not rrt.continues(a, b - 1e-3)
        checks = rrt.checks
        assert rrt.grow(WallBudget(10.0), 5.0)
        assert rrt.checks > checks
        assert rrt.continues(a, b)  # solved, not yet taken
        points, _ = rrt.path(WallBudget(1.0))
        assert points is not None
        assert not rrt.continues(a, b)  # taken: the next plan begins anew
    finally:
        rrt.close()


def test_interpolation_is_checked_between_its_points(robots) -> None:
    """A joint step that would jump the plate: the path stops before it."""
    robot = robots["panda"]
    a, b, world = _across_a_plate(robot)
    search = IkSearch(robot, "panda_hand", world, IkSearchSettings())
    plan = interpolate_checked(a, b, 2.0, search, WallBudget(1.0))
    assert plan.path is not None
    assert plan.note.startswith("collision ahead")
    assert search.path_free(plan.path)
    assert np.max(np.abs(plan.path[-1] - b)) > 0.1


def test_jt_tracks_a_free_space_step() -> None:
    scenario = load_scenario(
        SCENARIOS / "cat_free_step.yaml", overrides={"duration": "2.0"}
    )
    trace = run_jt(scenario)
    m = run_metrics(trace)
    assert m["reached"], m
    assert m["response_time_s"] < 0.1
    assert trace.periods == []  # torque control: no command periods


def test_cbp_compare_writes_one_report(tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    result = run_cbp(
        "compare",
        str(SCENARIOS / "cat_free_step.yaml"),
        "--methods",
        "jt,ik",
        "--set",
        "duration=1.0",
        "--out",
        str(out),
    )
    assert result.returncode == 0, result.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics) == {"jt", "ik"}
    report = (out / "report.md").read_text()
    assert "| metric | jt | ik |" in report
    assert (out / "goal.csv").read_text().startswith("t,x,y,z,qx,qy,qz,qw")
    assert (out / "trace_jt.csv").exists()
    assert (out / "trace_ik.csv").exists()
    bad = run_cbp(
        "compare", str(SCENARIOS / "cat_free_step.yaml"), "--methods", "cat,jtt"
    )
    assert bad.returncode == 2
    assert "'jt'" in bad.stderr


# The paper's head camera: the space under and beside the arm stays unseen.
HEAD_CAMERA_ONLY = (
    "[{name: head, position: [-0.35, 0.0, 1.15], target: [0.55, 0.0, 0.15]}]"
)


@pytest.mark.slow
def test_ik_that_finds_no_solution_in_the_map_says_why_once() -> None:
    """With the head camera alone, unseen space blocks every IK solution of free_step.

    The run says so once (not every period), names unknown space as the
    likely reason, and the arm holds without contact; with unseen space free
    the same goal is reached and nothing is said.
    """
    from cbp.executors.ik import run_ik
    from cbp.metrics import run_metrics

    path = Path(__file__).resolve().parents[2] / "scenarios" / "cat_free_step.yaml"
    runs = {}
    for unknown in ("occupied", "free"):
        scenario = load_scenario(
            path,
            overrides={
                "method.name": "ik",
                "perception.source": "depth_camera",
                "perception.cameras": HEAD_CAMERA_ONLY,
                "perception.unknown": unknown,
                **VIRTUAL_CLOCK,
            },
        )
        trace = run_ik(scenario)
        said = [m for _, m in trace.events if "no collision-free IK solution" in m]
        runs[unknown] = (run_metrics(trace), said)
    blocked, said = runs["occupied"]
    assert len(said) == 1, said
    assert "space no camera has seen counts as an obstacle" in said[0]
    assert not blocked["reached"]
    assert blocked["peak_contact_force_n"] == 0.0
    free, said = runs["free"]
    assert free["reached"], free
    assert said == []


def test_a_failed_search_is_not_repeated_until_something_changes(
    boards: Scenario,
) -> None:
    """Same goal, configuration and world: no second search; a new world: one."""
    from cbp.collision import PrimitiveEnvironment

    run = build_run(boards, method="ik")
    try:
        search = IkSearch(boards.robot, run.ee_frame, run.world, IkSearchSettings())
        out_of_reach = pin.SE3(np.eye(3), np.array([2.0, 0.0, 0.5]))
        q = boards.q0.copy()
        assert search.solution_for(out_of_reach, q, WallBudget(10.0)) is None
        first = search.solves
        assert first > 0
        assert search.solution_for(out_of_reach, q, WallBudget(10.0)) is None
        assert search.solves == first  # nothing changed: not searched again
        moved = q.copy()
        moved[0] += 0.01
        assert search.solution_for(out_of_reach, moved, WallBudget(10.0)) is None
        second = search.solves
        assert second > first  # the arm moved: searched again
        run.world.set_environment(PrimitiveEnvironment([]))
        assert search.solution_for(out_of_reach, moved, WallBudget(10.0)) is None
        assert search.solves > second  # a new world: searched again
        # A search cut short by its budget is not remembered as failed.
        cut = IkSearch(boards.robot, run.ee_frame, run.world, IkSearchSettings())
        assert cut.solution_for(out_of_reach, q, WallBudget(0.0)) is None
        assert cut._failed is None
    finally:
        run.finish()


@pytest.mark.parametrize("new_world", [False, True])
def test_a_search_cut_short_goes_on_where_it_stopped(
    boards: Scenario, new_world: bool
) -> None:
    """Over several small budgets the search tries each start once, then stops.

    Also when the world is new at each call (a map snapshot each period):
    then it is searched again only in the next new world.
    """
    from cbp.collision import PrimitiveEnvironment
    from cbp.methods.settings import VirtualCosts
    from cbp.run.budget import VirtualBudget

    run = build_run(boards, method="ik")
    try:
        # Every solve runs all its iterations (none given up as stalled).
        settings = IkSearchSettings(stall_iterations=0)
        search = IkSearch(boards.robot, run.ee_frame, run.world, settings)
        out_of_reach = pin.SE3(np.eye(3), np.array([2.0, 0.0, 0.5]))
        q = boards.q0.copy()
        whole = IkSearch(boards.robot, run.ee_frame, run.world, settings)
        assert whole.solve(out_of_reach, q, WallBudget(10.0)) is None
        assert whole.solves == len(whole.attempts(q)) * settings.max_iterations
        # Each budget holds about two starts' iterations (80 x 26 us each).
        calls = 0
        while search._failed is None:
            if new_world:
                run.world.set_environment(PrimitiveEnvironment([]))
            budget = VirtualBudget(0.004, VirtualCosts())
            assert search.solution_for(out_of_reach, q, budget) is None
            calls += 1
            assert calls < 200  # begun anew in each world, it would never end
        assert calls > 5  # it took several calls ...
        assert search.solves == whole.solves  # ... and tried every start once
        # Tried out against the last world: not searched again in it.
        assert search.solution_for(out_of_reach, q, WallBudget(10.0)) is None
        assert search.solves == whole.solves
        if new_world:  # ... but in the next one
            run.world.set_environment(PrimitiveEnvironment([]))
            assert search.solution_for(out_of_reach, q, WallBudget(10.0)) is None
            assert search.solves == 2 * whole.solves
    finally:
        run.finish()


def test_the_search_tries_random_starts_after_the_sweep(robots) -> None:
    """After the redundant joint's sweep come seeded random starts, within the limits."""
    robot = robots["panda"]
    settings = IkSearchSettings()
    search = IkSearch(robot, "panda_hand", None, settings)
    q = robot.home()
    starts = search.attempts(q)
    swept = IkSearch(robot, "panda_hand", None, IkSearchSettings(random_starts=0))
    sweep = swept.attempts(q)
    assert len(starts) == len(sweep) + settings.random_starts
    for (a, fixed_a), (b, fixed_b) in zip(starts, sweep, strict=False):
        assert fixed_a == fixed_b
        np.testing.assert_array_equal(a, b)
    randoms = np.array([seed for seed, fixed in starts[len(sweep) :]])
    assert all(fixed is None for _, fixed in starts[len(sweep) :])
    margin = settings.limit_margin
    assert np.all(randoms >= robot.lower_limits + margin)
    assert np.all(randoms <= robot.upper_limits - margin)
    assert np.min(np.ptp(randoms, axis=0)) > 0.5  # spread over the joint ranges
    again = IkSearch(robot, "panda_hand", None, settings).attempts(q)
    for (a, _), (b, _) in zip(starts, again, strict=True):
        np.testing.assert_array_equal(a, b)  # the same stream in every run


def test_the_compiled_least_squares_step_agrees_with_numpy(robots) -> None:
    """The search's step equals -J^T (J J^T + d I)^-1 e, clipped, with a joint held or not."""
    from cbp.executors.ik_search import DAMPING, dls_step

    robot = robots["panda"]
    model, data = robot.model, robot.model.createData()
    frame = robot.frame_id("panda_hand")
    rng = np.random.default_rng(3)
    lower, upper = robot.lower_limits, robot.upper_limits
    out = np.empty(model.nv)
    for k in range(50):
        q = rng.uniform(lower, upper)
        goal = pin.SE3.Random()
        pin.framesForwardKinematics(model, data, q)
        error = goal.actInv(data.oMf[frame])
        err = pin.log6(error).vector
        J = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL)
        held = -1 if k % 2 else k % model.nv
        dls_step(err, J, pin.Jlog6(error), held, DAMPING, q, lower, upper, True, out)
        Jt = pin.Jlog6(error).dot(J)
        if held >= 0:
            Jt[:, held] = 0.0
        step = -Jt.T.dot(np.linalg.solve(Jt.dot(Jt.T) + DAMPING * np.eye(6), err))
        expected = np.clip(q + step, lower, upper)
        np.testing.assert_allclose(
            out, expected, rtol=0, atol=1e-9 * (1 + np.abs(step).max())
        )
        if held >= 0:
            assert out[held] == q[held]
