"""``cbp teleop``: a live session driven through its own interface and a browser.

Sessions run the real simulation in real time (PyBullet, CAT and the others),
so the tests that drive one are slow. The browser test opens the page in
headless Chromium (Debian's ``chromium`` and ``chromium-driver``), clicks a jog
button and the method selector, and keeps a screenshot as an artifact in
``out/test-artifacts/``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cbp.compare import compare
from cbp.errors import ConfigError
from cbp.goals import recorded_goal_overrides
from cbp.metrics import run_metrics
from cbp.plugin import HoldsContacts
from cbp.scenario import load_scenario
from cbp.teleop import GOAL_FILE, LiveGoal, TeleopSession
from tests.conftest import (
    free_port,
    headless_chromium,
    run_cbp,
    teleop_process,
    wait_until,
)

ROOT = Path(__file__).resolve().parents[1]
BOARDS = ROOT / "scenarios" / "cat_boards.yaml"
ARTIFACTS = ROOT / "out" / "test-artifacts"


def test_jogs_move_the_goal_in_world_or_hand_axes() -> None:
    session = TeleopSession(BOARDS, "cat")
    p0, R0 = session.goal.pose()
    session.jog("x", 0.02)
    p1, R1 = session.goal.pose()
    np.testing.assert_allclose(p1 - p0, [0.02, 0.0, 0.0])
    np.testing.assert_array_equal(R1, R0)
    session.jog("z", 0.05, frame="hand")  # along the hand's own z
    p2, _ = session.goal.pose()
    np.testing.assert_allclose(p2 - p1, 0.05 * R0[:, 2], atol=1e-12)
    session.jog("rz", np.pi / 2, frame="hand")
    _, R3 = session.goal.pose()
    np.testing.assert_allclose(R3[:, 2], R0[:, 2], atol=1e-12)  # about it
    np.testing.assert_allclose(R3[:, 0], R0[:, 1], atol=1e-12)
    session.reset()
    np.testing.assert_allclose(session.goal.pose()[0], p0)
    with pytest.raises(ConfigError, match="axis"):
        session.jog("w", 0.1)
    with pytest.raises(ConfigError, match="method"):
        session.switch("jt")  # not a trajectory executor
    with pytest.raises(ConfigError, match="method"):
        TeleopSession(BOARDS, "velocity")


def test_the_live_goal_reports_each_sampled_goal_once() -> None:
    goal = LiveGoal(np.zeros(3), np.eye(3))
    first = goal.set(np.ones(3), np.eye(3))
    second = goal.set(2 * np.ones(3), np.eye(3))
    assert (first, second) == (1, 2)
    position, _ = goal.sample(0.0)
    np.testing.assert_array_equal(position, 2 * np.ones(3))
    taken = goal.take_sampled()
    assert taken is not None
    assert taken[0] == 2
    assert taken[1] <= taken[2]  # arrived before it was sampled
    assert goal.take_sampled() is None  # measured once; 1 was never sampled


def test_compare_refuses_a_goal_file_it_cannot_read(tmp_path: Path) -> None:
    bad = tmp_path / "goal.csv"
    bad.write_text("t,x\n0,1\n")
    result = run_cbp("compare", str(BOARDS), "--goal", str(bad))
    assert result.returncode == 2
    assert "--goal" in result.stderr


@pytest.mark.slow
def test_a_scripted_session_is_recorded_and_replays(tmp_path: Path) -> None:
    """Goals sent through the session's interface; the recording replays them.

    Also: a NaN goal is rejected with an event and the arm keeps the previous
    one; switching methods takes effect at the next period; stopping brakes.
    """
    session = TeleopSession(BOARDS, "cat")
    session.start()
    try:
        assert wait_until(lambda: session.snapshot().t > 0.5, 10)
        start = session.snapshot().hand
        for _ in range(5):
            session.jog("x", 0.03)
            time.sleep(0.4)
        assert wait_until(lambda: session.snapshot().hand[0] - start[0] > 0.14, 5)
        session.set_goal(np.array([np.nan, 0.0, 0.0]), np.eye(3))
        time.sleep(0.3)
        session.switch("ik")
        assert wait_until(lambda: session.snapshot().method == "ik", 10)
        session.jog("z", 0.05)
        time.sleep(1.5)
    finally:
        trace = session.stop()
    events = [message for _, message in trace.events]
    assert any(m.startswith("goal rejected") for m in events)
    assert "method switched from cat to ik" in events
    assert np.all(np.isfinite(trace.q))
    live = run_metrics(trace, session.scenario.robot)
    assert live["peak_contact_force_n"] == 0.0
    assert trace.aborted is None
    assert session.latency_ms(), "no goal-to-command latency was measured"

    out = tmp_path / "session"
    goal_file = session.write(out)
    assert goal_file == out / GOAL_FILE
    assert json.loads((out / "metrics.json").read_text())["cat"]["samples"] > 0
    # Replayed to CAT alone, the recording ends where the live session ended.
    replay = compare(
        BOARDS,
        ["cat"],
        tmp_path / "replay",
        overrides=recorded_goal_overrides(goal_file),
    )
    metrics = replay.metrics["cat"]
    assert metrics["peak_contact_force_n"] == 0.0
    replayed = np.loadtxt(tmp_path / "replay" / "trace.csv", delimiter=",", skiprows=1)
    header = (tmp_path / "replay" / "trace.csv").read_text().splitlines()[0].split(",")
    hand = replayed[-1, [header.index(f"ee_{c}") for c in "xyz"]]
    goal, _ = session.goal.pose()
    # The live run ended with IK in control; both end at the last goal.
    assert np.linalg.norm(hand - goal) < 0.01
    assert np.linalg.norm(trace.ee_position[-1] - goal) < 0.01


@pytest.mark.slow
def test_the_page_jogs_the_hand_and_switches_the_method() -> None:
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from selenium.webdriver.common.by import By

    from cbp.teleop.goal_page import TeleopPage

    session = TeleopSession(BOARDS, "cat")
    page = TeleopPage(session, port=free_port())
    assert page.server.get_host() == "127.0.0.1"  # localhost unless asked
    session.start()
    page.start()
    browser = headless_chromium()
    try:
        browser.get(page.url)

        def button(label: str):  # type: ignore[no-untyped-def]
            found = browser.find_elements(
                By.XPATH, f"//button[normalize-space()='{label}']"
            )
            return found[0] if found else None

        assert wait_until(lambda: button("+x") is not None, 60), "the panel never came"
        assert wait_until(lambda: browser.find_elements(By.TAG_NAME, "canvas"), 30)
        assert wait_until(lambda: "goal error" in browser.page_source, 10)
        time.sleep(1.0)  # let the robot be drawn
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        shot = ARTIFACTS / "teleop_page.png"
        browser.save_screenshot(str(shot))
        from PIL import Image

        pixels = np.asarray(Image.open(shot).convert("L"), dtype=float)
        assert pixels.std() > 5.0, "the screenshot is blank"

        # The page draws the robot where the simulation has it.
        snap = session.snapshot()
        drawn = page.state().robot_q
        assert drawn is not None
        np.testing.assert_allclose(drawn[:7], snap.q[:7], atol=0.05)

        # A jog button moves the simulated hand by the step (how soon is the
        # latency benchmark's: here it must only happen, on a loaded machine too).
        before = session.snapshot().hand.copy()
        step = float(page.step.value)
        button("+x").click()
        assert wait_until(
            lambda: session.snapshot().hand[0] - before[0] > 0.9 * step, 10.0
        ), f"the hand moved {session.snapshot().hand - before} in 10 s"
        assert wait_until(lambda: not page.state().unreachable, 10.0)  # within reach

        # The keyboard: "w" presses +x (a shortcut in the page).
        assert "keys: w +x" in browser.page_source
        before = session.snapshot().hand.copy()
        browser.find_element(By.TAG_NAME, "body").send_keys("w")
        assert wait_until(
            lambda: session.snapshot().hand[0] - before[0] > 0.9 * step, 10.0
        ), "the w key did not move the hand"

        # The method selector hands control to IK at the next period.
        selector = browser.find_element(
            By.XPATH, "//*[normalize-space()='method']/following::input[1]"
        )
        selector.click()
        assert wait_until(
            lambda: browser.find_elements(By.XPATH, "//*[@role='option']"), 5
        )
        option = browser.find_element(
            By.XPATH, "//*[@role='option'][normalize-space()='ik']"
        )
        option.click()
        assert wait_until(lambda: session.snapshot().method == "ik", 10)

        # A goal inside a board, sent from elsewhere (a script): the gizmo
        # follows it; the arm stops short, and the page draws the goal as a
        # gripper and the posture the arm stopped in (the CAT paper's operator
        # view).
        session.switch("cat")
        _, rotation = session.goal.pose()
        inside = np.array([0.55, -0.24, 0.03])  # board_1's centre
        session.set_goal(inside, rotation)
        assert wait_until(lambda: np.allclose(page.gizmo.position, inside), 10.0)
        assert page.scene.ghost is not None
        assert wait_until(
            lambda: page.state().gripper_visible and page.state().ghost_visible, 8.0
        )
        snap = session.snapshot()
        assert snap.contacts is not None
        assert len(snap.contacts.distance) > 0  # CAT's contact rows are drawn
        # Why it holds, as a state: the goal inside the board; red arrows of
        # the blocked directions at the contacts holding the arm; the board
        # translucent; a legend; all in the browser too.
        state = page.state()
        assert state.hold is not None
        assert state.hold.kind == "goal in obstacle"
        assert state.blocked_arrows > 0
        assert state.xray
        assert "closest posture" in " ".join(state.legend)

        def text() -> str:
            return str(browser.execute_script("return document.body.innerText"))

        assert wait_until(
            lambda: "holds: the goal lies inside an obstacle" in text(), 5
        )
        assert "legend" in text()
        assert "blocked direction at a contact" in text()

        # A browser that goes away leaves the arm on its goal: nothing is sent,
        # the session runs on.
        count, goal = session.goal.count, session.goal.pose()[0]
        t = session.snapshot().t
        browser.quit()
        assert wait_until(lambda: not page.server.get_clients(), 5)
        time.sleep(1.0)
        assert session.goal.count == count
        np.testing.assert_array_equal(session.goal.pose()[0], goal)
        assert session.running
        assert session.snapshot().t > t + 0.9
    finally:
        browser.quit()
        page.close()
        trace = session.stop()
    assert "method switched from cat to ik" in [m for _, m in trace.events]
    assert run_metrics(trace, session.scenario.robot)["peak_contact_force_n"] == 0.0


@pytest.mark.slow
def test_orbit_and_pan_are_driven_live_and_switched(tmp_path: Path) -> None:
    """The orbit paper's operator inputs: camera-frame velocity and distance.

    Orbit object runs first; the distance is raised and the camera moved
    sideways; then pan object takes over within the run, from the last command.
    """
    from cbp.teleop import InputSession

    scenarios = ROOT / "scenarios"
    session = InputSession(
        [scenarios / "youbot_orbit_case1.yaml", scenarios / "youbot_pan.yaml"]
    )
    assert list(session.loops) == ["youbot_orbit_case1", "youbot_pan"]
    session.start()
    try:
        assert wait_until(lambda: session.t > 6.0, 15)  # past the start's transient
        session.set_input("distance", np.array([0.7]))
        session.set_input("user_velocity", np.array([0.1, 0.0]))
        assert wait_until(lambda: session.t > 12.0, 15)
        orbit = session.snapshot().signals
        assert orbit["distance"] == pytest.approx(0.7, abs=0.01)
        session.switch("youbot_pan")
        session.set_input("user_velocity", np.array([0.0, 0.0, 0.05]))
        start = session.t
        assert wait_until(lambda: session.t > start + 3.0, 10)
        assert session.snapshot().active == "youbot_pan"
    finally:
        traces = session.stop()
    assert set(traces) == {"youbot_orbit_case1", "youbot_pan"}
    orbit_trace = traces["youbot_orbit_case1"]
    assert orbit_trace.inputs is not None
    assert orbit_trace.inputs["distance"][-1][0] == pytest.approx(0.7)
    assert "switched from youbot_orbit_case1 to youbot_pan" in [
        m for _, m in traces["youbot_pan"].events
    ]
    # Continuous across the switch: no jump in the command.
    u = np.vstack([orbit_trace.u, traces["youbot_pan"].u])
    robot = session.robot
    assert np.all(
        np.abs(np.diff(u, axis=0)) <= 1.01 * robot.acceleration_limits * 0.02 + 1e-9
    )
    session.write(traces, tmp_path / "live")
    metrics = json.loads((tmp_path / "live" / "metrics.json").read_text())
    assert set(metrics) == {"youbot_orbit_case1", "youbot_pan"}


@pytest.mark.slow
def test_the_orbit_page_sends_sliders_and_switches_configurations() -> None:
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from cbp.teleop import InputSession
    from cbp.teleop.inputs_page import InputsPage

    scenarios = ROOT / "scenarios"
    session = InputSession(
        [scenarios / "youbot_orbit_case1.yaml", scenarios / "youbot_pan.yaml"]
    )
    page = InputsPage(session, port=free_port())
    try:
        assert page.server.get_host() == "127.0.0.1"
        page.sliders["youbot_orbit_case1"]["distance"][0].value = 0.7
        assert wait_until(
            lambda: session.inputs["youbot_orbit_case1"]["distance"][0] == 0.7, 10
        )
        page.config.value = "youbot_pan"
        assert wait_until(lambda: session.active == "youbot_pan", 10)
        assert page.folders["youbot_pan"].visible
        assert not page.folders["youbot_orbit_case1"].visible
        page.update()
        assert "youbot_pan" in page.readout.content
    finally:
        page.close()
        session.stop()


@pytest.mark.slow
def test_the_page_draws_the_map_and_unknown_space_on_the_toggle() -> None:
    """With cameras: the occupied cells, and the unknown ones when asked."""
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from cbp.perception.kernels import OCCUPIED
    from cbp.teleop.goal_page import MAX_CELLS, TeleopPage

    session = TeleopSession(BOARDS, "cat", {"perception.source": "depth_camera"})
    page = TeleopPage(session, port=free_port())
    try:
        page.update()
        assert session.parts.cameras is not None
        occupied = session.parts.cameras.grid.count(OCCUPIED)
        assert occupied > 0
        assert page.state().map_cells == min(occupied, MAX_CELLS)
        page.show_unknown.value = True
        page.update()
        assert page.state().map_cells > min(occupied, MAX_CELLS - 1)
        assert page.state().map_cells <= MAX_CELLS
    finally:
        page.close()
        session.parts.close()


def test_the_page_gets_the_obstacle_contacts_of_every_contact_row() -> None:
    """Obstacle contacts of each constraint that holds contacts; no self pairs.

    CAT's configuration has two (contact_normals, self_collision); a user's
    own contact constraint (another type name) is added. The page's set is
    their obstacle contacts, the same object until a row latches anew.
    """
    from cbp.engine import Engine
    from cbp.plugins.constraints.contact_normals_constraint import (
        ContactNormalsConstraint,
        ContactParams,
    )
    from cbp.qp import Entry

    class Mine(ContactNormalsConstraint):
        type_name = "my_contacts"

    session = TeleopSession(BOARDS, "cat")
    planner = session.planner
    cat = planner.planner("cat")
    robot, world = session.scenario.robot, session.scenario.world_for_run()
    mine = Mine(ContactParams(), robot, "mine")
    mine.attach_world(world)
    cat.engine = engine = Engine(
        robot, [*cat.engine.entries, Entry.make(mine)], solver="daqp"
    )
    holders = {
        e.plugin.type_name: e.plugin
        for e in engine.entries
        if isinstance(e.plugin, HoldsContacts)
    }
    assert set(holders) == {"contact_normals", "self_collision", "my_contacts"}
    # Toward a goal inside a board until the arm is near it (steps, no simulator).
    session.scenario.goal_task().set_target(np.array([0.55, -0.24, 0.03]), np.eye(3))
    q = session.scenario.q0.copy()
    for _ in range(300):
        q = robot.integrate(q, engine.step(q, 0.02).dq)
        if len(holders["contact_normals"].contacts) and len(
            holders["self_collision"].contacts
        ):
            break
    assert len(holders["self_collision"].contacts) > 0
    obstacles = holders["contact_normals"].contacts
    assert len(obstacles) > 0
    shown = planner.contacts()
    assert shown is not None
    assert (shown.other_shape == -1).all()  # no self pairs
    # contact_normals' and the user's rows (the same world: the same contacts).
    np.testing.assert_array_equal(
        np.sort(shown.distance), np.sort(np.r_[obstacles.distance, obstacles.distance])
    )
    assert planner.contacts() is shown  # unchanged: not merged again
    engine.step(q, 0.02)
    assert planner.contacts() is not shown


def test_absurd_or_unreachable_operator_goals_are_refused_or_clamped() -> None:
    """1e300 m and 1e12 m are refused; beyond reach or under the floor, clamped."""
    from cbp.run import build_run
    from cbp.run.goal_input import GoalBounds

    scenario = load_scenario(BOARDS)
    session_goal = LiveGoal(np.array([0.4, 0.0, 0.4]), np.eye(3))
    parts = build_run(scenario, method="cat", goal=session_goal)
    try:
        goal = parts.goal
        first = goal.send(0.0)
        assert first is not None
        np.testing.assert_allclose(first.translation, [0.4, 0.0, 0.4])
        bounds = GoalBounds.of(scenario)
        assert 0.85 < bounds.reach < 1.1  # the Panda's chain, added up
        for k, far in enumerate((1e300, 1e12), start=1):
            session_goal.set(np.array([far, 0.0, 0.4]), np.eye(3))
            kept = goal.send(k / 30)
            assert kept is not None
            np.testing.assert_allclose(kept.translation, [0.4, 0.0, 0.4])
        session_goal.set(np.array([3.0, 0.0, 0.4]), np.eye(3))  # out of reach
        clamped = goal.send(3 / 30)
        assert clamped is not None
        assert bounds.centre is not None
        distance = np.linalg.norm(clamped.translation - bounds.centre)
        assert distance == pytest.approx(bounds.reach)
        session_goal.set(np.array([0.4, 0.0, -2.0]), np.eye(3))  # under the table
        under = goal.send(4 / 30)
        assert under is not None
        assert under.translation[2] >= scenario.spec.perception.bounds[0][2] - 1e-12
        session_goal.set(np.array([0.4, 0.1, 0.4]), np.eye(3))
        goal.send(5 / 30)
    finally:
        parts.close()
    events = [m for _, m in parts.log.events]
    # The two refused in a row are one episode: said once, counted when the
    # next goal is taken.
    assert sum(m.startswith("goal rejected") for m in events) == 1
    assert "goal accepted again after 2 rejected sample(s) since 0.03 s" in events
    assert parts.log.counters["rejected_goal_samples"] == 2
    assert any("beyond its reach" in m for m in events)
    assert any("outside the world's bounds" in m for m in events)
    assert "goal within the world's bounds and the arm's reach again" in events


def test_a_scenario_stream_is_not_clamped() -> None:
    """A scenario's own goal beyond reach (the paper's) is taken as written."""
    from cbp.run import build_run

    scenario = load_scenario(ROOT / "scenarios" / "cat_unreachable.yaml")
    parts = build_run(scenario, method="cat")
    try:
        goals = [parts.goal.send(t) for t in np.arange(0.0, 6.0, 0.5)]
    finally:
        parts.close()
    assert not [m for _, m in parts.log.events if "clamped" in m]
    assert max(np.linalg.norm(g.translation[:2]) for g in goals if g) > 1.0


def test_a_goal_moved_twice_within_one_sample_is_recorded_once() -> None:
    """The recorded goal times strictly increase, so the recording replays."""
    from cbp.run import build_run

    live = LiveGoal(np.array([0.4, 0.0, 0.4]), np.eye(3), rate_hz=30.0)
    parts = build_run(load_scenario(BOARDS), method="cat", goal=live)
    try:
        parts.goal.send(0.0)
        live.set(np.array([0.45, 0.0, 0.4]), np.eye(3))
        parts.goal.resend(0.01)  # a planner takes the newer goal mid-period
        live.set(np.array([0.5, 0.0, 0.4]), np.eye(3))
        parts.goal.resend(0.02)  # and again, within the same 1/30 s sample
    finally:
        parts.close()
    times = [t for t, _ in parts.goal.changes]
    assert np.all(np.diff(times) > 0), times
    np.testing.assert_allclose(parts.goal.changes[-1][1].translation, [0.5, 0, 0.4])


def test_hangup_and_terminate_both_stop_a_session() -> None:
    """SIGHUP stops a session as SIGTERM does (the slow test sends SIGTERM)."""
    import signal

    from cbp.teleop.serve import STOP_SIGNALS

    assert set(STOP_SIGNALS) == {signal.SIGTERM, signal.SIGHUP}


@pytest.mark.slow
@pytest.mark.parametrize("signal_name", ["SIGTERM"])
def test_a_signal_ends_a_session_that_saves_and_replays(
    tmp_path: Path, signal_name: str
) -> None:
    """SIGTERM to `cbp teleop`: the outputs are written and replay."""
    import signal

    pytest.importorskip("viser", reason="the viewer extra is not installed")
    out = tmp_path / "session"
    with teleop_process(str(BOARDS), "--out", str(out)) as (process, said):
        assert "teleoperation of" in said, said
        time.sleep(2.0)  # the session runs
        process.send_signal(getattr(signal, signal_name))
        rest, _ = process.communicate(timeout=300)
    assert process.returncode == 0, rest
    assert f"{signal_name}: stopping and saving" in rest
    goal_file = out / GOAL_FILE
    assert goal_file.is_file()
    assert json.loads((out / "metrics.json").read_text())
    replay = run_cbp(
        "compare",
        str(BOARDS),
        "--goal",
        str(goal_file),
        "--methods",
        "cat",
        "--out",
        str(tmp_path / "replay"),
        "--set",
        "duration=1",
        "--set",
        "method.cat.timing.clock=virtual",
    )
    assert replay.returncode == 0, replay.stderr


def test_a_goal_set_tells_the_listeners_and_wakes_the_loop_at_once() -> None:
    """set_goal, jog and reset each tell the listeners; the loop's sample quiets it."""
    session = TeleopSession(BOARDS, "cat")
    told: list[int] = []
    session.listen(lambda: told.append(session.goal.count))
    assert not session.goal.arrived.is_set()
    session.jog("x", 0.02)
    assert told == [1]
    assert session.goal.arrived.is_set()  # the pacer's wait ends on it
    session.goal.sample(0.0)
    assert not session.goal.arrived.is_set()
    session.set_goal(*session.goal.pose())
    session.reset()
    assert told == [1, 2, 3]


@pytest.fixture
def boards_page() -> Iterator[tuple[TeleopSession, Any]]:
    """A CAT session on the boards and its page, not started; closed after."""
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from cbp.teleop.goal_page import TeleopPage

    session = TeleopSession(BOARDS, "cat")
    page = TeleopPage(session, port=free_port())
    try:
        yield session, page
    finally:
        page.close()
        session.parts.close()
        session.planner.close()


def test_the_page_updates_on_a_goal_change_without_a_sampling_tick(
    boards_page: tuple[TeleopSession, Any],
) -> None:
    """With no idle updates at all, a goal set from a script still reaches the page."""
    session, page = boards_page
    # Not one idle update in a day: only the session's changes wake it.
    page.start(idle_rate=1.0 / 86400.0, while_running=False)
    assert wait_until(lambda: page.updates >= 1, 60.0), "no first update"
    assert page.update_causes == ["idle"]  # the first, at the start
    position, rotation = session.goal.pose()
    moved = position + np.array([0.0, 0.03, 0.0])
    session.set_goal(moved, rotation)
    assert wait_until(lambda: page.updates >= 2, 60.0), "the change was not shown"
    assert page.update_causes[:2] == ["idle", "change"]
    np.testing.assert_allclose(page.state().goal_position, moved)


def test_the_page_sends_a_path_again_only_when_it_looks_different(
    boards_page: tuple[TeleopSession, Any],
) -> None:
    """A new trajectory drawing the same hand path is not sent; a moved one is."""
    import dataclasses

    session, page = boards_page
    sim = session.parts.arm
    q0 = np.array(sim.q, dtype=float)
    moving = dataclasses.replace(
        sim.trajectory,
        times=np.array([0.0, 1.0]),
        positions=np.stack([q0, q0 + 0.2]),
        velocities=np.zeros((2, q0.size)),
        accelerations=np.zeros((2, q0.size)),
    )
    sim.follow(moving)
    page.update()
    drawn = page.scene.path_lines
    assert drawn is not None
    assert len(drawn) > 0
    sim.follow(dataclasses.replace(moving))  # a new object, the same path
    page.update()
    assert page.scene.path_lines is drawn  # not sent again
    sim.follow(dataclasses.replace(moving, positions=np.stack([q0, q0 - 0.2])))
    page.update()
    assert page.scene.path_lines is not drawn


def _moved_robot(session: TeleopSession, by: float) -> np.ndarray:
    """Simulate the (not started) session's arm moving every joint by ``by``."""
    import dataclasses

    sim = session.parts.arm
    q0 = np.array(sim.q, dtype=float)
    t = float(sim.t)
    sim.follow(
        dataclasses.replace(
            sim.trajectory,
            times=np.array([t, t + 0.05]),
            positions=np.stack([q0, q0 + by]),
            velocities=np.zeros((2, q0.size)),
            accelerations=np.zeros((2, q0.size)),
        )
    )
    sim.run_until(t + 0.3)
    return np.array(sim.q, dtype=float)


def test_the_robot_pose_is_sent_at_a_change_before_the_next_update(
    boards_page: tuple[TeleopSession, Any],
) -> None:
    """The arm's moved pose is sent at the change, not at the update interval's end."""
    session, page = boards_page
    # One update a minute at most: the pose goes out on its own meanwhile.
    page.start(max_rate=1.0 / 60.0, idle_rate=1.0 / 60.0, while_running=False)
    assert wait_until(lambda: page.updates >= 1, 60.0), "no first update"
    drawn = page.state().robot_q
    assert drawn is not None
    q = _moved_robot(session, 0.02)
    session.changes.notify()
    assert wait_until(lambda: not np.allclose(page.state().robot_q, drawn), 60.0), (
        "the moved arm was not sent"
    )
    assert page.updates == 1  # no update of the rest: the pose alone
    assert page.first_sent >= 1
    np.testing.assert_allclose(page.state().robot_q[:7], q[:7], atol=2e-4)


def test_the_page_never_shows_a_pose_before_its_time(
    boards_page: tuple[TeleopSession, Any],
) -> None:
    """A pose simulated ahead of the wall clock is drawn only once its time comes."""
    session, page = boards_page
    page.update()
    drawn = page.state().robot_q
    assert drawn is not None
    _moved_robot(session, 0.02)
    # The loop's clock: the simulated state is a minute ahead of now.
    session._pacer.start(session.parts.arm.t - 60.0)
    page.update()
    np.testing.assert_array_equal(page.state().robot_q, drawn)
    session._pacer.start(session.parts.arm.t)  # its time is now
    page.update()
    assert not np.allclose(page.state().robot_q, drawn)


def test_a_robot_pose_sends_only_the_joints_that_moved() -> None:
    """Posing matches viser's full update, within tolerance, joint by joint."""
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    import viser

    from cbp.drawing import RobotPose, add_robot
    from cbp.scene_file import scene_description

    urdf = scene_description(load_scenario(BOARDS), duration=0.0)["urdf"]
    server = viser.ViserServer(port=free_port(), verbose=False)
    try:
        full = add_robot(server, urdf, "/full", (200, 200, 200))
        posed = add_robot(server, urdf, "/posed", (200, 200, 200))
        pose = RobotPose(posed, 1e-3)
        rng = np.random.default_rng(3)
        q = rng.uniform(-0.5, 0.5, len(full.get_actuated_joint_names()))
        q[-1] = 0.02  # a finger (prismatic; its twin mimics it)
        assert pose.pose(q)
        for _ in range(5):
            q = q + rng.normal(0.0, 0.05, q.size) * (rng.random(q.size) < 0.5)
            q[-1] = abs(q[-1])
            pose.pose(q)
            full.update_cfg(q)
            frames = zip(full.joint_frames(), posed.joint_frames(), strict=True)
            for (_, a), (_, b) in frames:
                wa, wb = np.array(a.wxyz), np.array(b.wxyz)
                np.testing.assert_allclose(wa * np.sign(wa @ wb), wb, atol=1e-9)
                np.testing.assert_allclose(a.position, b.position, atol=1e-9)
        assert not pose.pose(q + 0.5e-3)  # within tolerance: nothing sent
        # A joint that did not move is not sent again: a mark on its frame stays.
        joint, frame = posed.joint_frames()[2]
        assert joint.name == "panda_joint3"
        frame.wxyz = (0.0, 1.0, 0.0, 0.0)
        moved = q.copy()
        moved[0] += 0.1
        assert pose.pose(moved)
        np.testing.assert_array_equal(frame.wxyz, (0.0, 1.0, 0.0, 0.0))
    finally:
        server.stop()


def test_a_second_session_with_the_same_output_folder_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A live session (or run) holds its folder: another one is refused, exit 2."""
    from cbp.cli import main
    from cbp.files import claim_output_folder

    out = tmp_path / "session"
    live = claim_output_folder(out)  # as a session still going holds it
    try:
        code = main(
            ["teleop", str(ROOT / "scenarios" / "cat_boards.yaml"), "--out", str(out)]
        )
    finally:
        live.release(remove=True)
    assert code == 2
    assert "is in use by a run still going" in capsys.readouterr().err
    assert not any(out.parent.glob(".session.part-*"))
