"""The velocity executor: orbit object (the orbit paper's two cases), pan object."""

from __future__ import annotations

import json
import textwrap
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cbp.errors import ConfigError, ScenarioError
from cbp.executors.kinematic import run_kinematic
from cbp.executors.velocity import run_velocity
from cbp.metrics import run_metrics
from cbp.scenario import Scenario, load_scenario
from cbp.state import RobotState
from cbp.trace import Trace
from tests.conftest import run_cbp

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@cache
def _run(name: str) -> tuple[Scenario, Trace, dict[str, Any]]:
    scenario = load_scenario(SCENARIOS / f"{name}.yaml")
    trace = run_velocity(scenario)
    return (
        scenario,
        trace,
        run_metrics(trace, scenario.robot),
    )


@pytest.mark.parametrize("case", ["youbot_orbit_case1", "youbot_orbit_case2"])
def test_orbit_keeps_every_constraint(case: str) -> None:
    """The issue's checks, from the trace: lag, view, roll, bounds, both move."""
    _, trace, m = _run(case)
    # The start's errors ask for more than the acceleration limits allow: the
    # first ticks scale them down, and nothing else happens.
    assert trace.events
    assert all(e.startswith("QP eased") and t < 0.2 for t, e in trace.events)
    assert m["distance_error_max_m"] < 0.02
    assert m["view_error_max_deg"] < 5.0
    assert m["roll_max_deg"] < 1.0
    s = trace.signals
    assert np.all(s["altitude"] >= s["min_altitude"])  # every sample, transient too
    assert np.all(s["obstacle_distance"] >= s["min_obstacle_distance"])
    assert m["base_travel_m"] > 0.3
    assert m["arm_travel_rad"] > 1.0
    # The view error decays from the start's ~30 deg.
    assert s["view_error_deg"][0] > 20.0
    assert np.all(s["view_error_deg"][trace.t >= m["transient_s"]] < 5.0)


@pytest.mark.parametrize(
    "case", ["youbot_orbit_case1", "youbot_orbit_case2", "youbot_pan"]
)
def test_commands_stay_within_the_acceleration_limits(case: str) -> None:
    """Every tick's command is within a_max dt of the one before (from rest)."""
    scenario, trace, m = _run(case)
    assert trace.u is not None
    u = np.vstack([np.zeros(scenario.robot.nv), trace.u])
    change = np.abs(np.diff(u, axis=0)) / 0.02  # [per s^2]
    assert np.all(change <= 1.01 * scenario.robot.acceleration_limits + 1e-6)
    assert m["max_joint_limit_violation_rad"] == 0.0


def test_the_orbit_constraint_brakes_before_a_joint_limit(robots) -> None:
    """A joint running at a limit slows so that it can stop before it."""
    from cbp.plugins.constraints.joint_acceleration_constraint import (
        JointAccelerationConstraint,
        JointAccelerationParams,
    )

    robot = robots["panda"]
    c = JointAccelerationConstraint(JointAccelerationParams(margin=0.05), robot)
    dt, a = 0.02, robot.acceleration_limits[0]
    q = robot.home()
    q[0] = robot.upper_limits[0] - 0.05 - 0.01  # 1 cm from where it must stop
    v = np.zeros(robot.nv)
    v[0] = 2.0  # far too fast to stop in 1 cm
    state = RobotState(robot, q)
    state.set_velocity(v)
    c.prepare(state, dt)
    lower, upper = c.compute_bounds(state)
    # As hard as it can, and no harder.
    assert upper[0] == pytest.approx((2.0 - a * dt) * dt)
    assert lower[0] == pytest.approx(upper[0])
    # From rest, toward the limit only as fast as it can stop in time.
    state.set_velocity(np.zeros(robot.nv))
    c.prepare(state, dt)
    lower, upper = c.compute_bounds(state)
    speed = upper[0] / dt
    assert 0.0 < speed <= a * dt
    assert speed * 1.5 * dt + speed**2 / (2 * a) <= 0.01 + 1e-12
    assert lower[0] == pytest.approx(-a * dt * dt)


def test_orbit_follows_the_desired_distance() -> None:
    """Case 1 changes r_d; the distance follows it up and back."""
    _, trace, _ = _run("youbot_orbit_case1")
    s = trace.signals
    at = {t: int(np.searchsorted(trace.t, t)) for t in (15.0, 32.0, 55.0)}
    assert s["distance"][at[15.0]] == pytest.approx(0.6, abs=5e-3)
    assert s["distance"][at[32.0]] == pytest.approx(0.75, abs=5e-3)
    assert s["distance"][at[55.0]] == pytest.approx(0.6, abs=5e-3)


def test_pan_translates_the_camera_along_its_own_axes() -> None:
    """Pan object: forward 0.5 m, then sideways 0.5 m, then up, without roll."""
    scenario, trace, m = _run("youbot_pan")
    robot = scenario.robot
    state = RobotState(robot)
    frame = robot.frame_id("camera_link")

    def pose(t: float) -> tuple[np.ndarray, np.ndarray]:
        state.update(trace.q[int(np.searchsorted(trace.t, t))])
        return state.frame_position(frame).copy(), state.frame_rotation(frame).copy()

    p0, R0 = pose(0.5)
    p1, _ = pose(7.0)
    p2, _ = pose(13.5)
    forward = R0.T.dot(p1 - p0)
    sideways = R0.T.dot(p2 - p1)
    assert forward[0] == pytest.approx(0.5, abs=0.05)
    assert abs(forward[1]) < 0.05
    assert sideways[1] == pytest.approx(0.5, abs=0.05)
    assert m["roll_max_deg"] < 1.0


def test_refused_input_keeps_the_previous_value(tmp_path: Path) -> None:
    """A desired distance that turns negative is refused, with an event."""
    path = tmp_path / "s.yaml"
    path.write_text(
        textwrap.dedent(
            f"""\
            name: bad_input
            include: {SCENARIOS / "configs" / "orbit.yaml"}
            duration: 2.0
            inputs:
              - entry: distance
                values: ["where(t > 1, -1, 0.6)"]
            """
        )
    )
    trace = run_velocity(load_scenario(path))
    refused = [msg for _, msg in trace.events if "refused" in msg]
    assert len(refused) == 49  # every tick after 1 s (1.02 s to 1.98 s)
    # The desired distance in effect stays the last accepted one.
    assert np.all(trace.signals["distance_desired"][trace.t > 1.0] == 0.6)
    assert np.all(np.isfinite(trace.q))


def test_input_errors_are_located(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(
        textwrap.dedent(
            f"""\
            name: bad
            include: {SCENARIOS / "configs" / "orbit.yaml"}
            duration: 2.0
            inputs:
              - entry: distanse
                values: [0.6]
              - entry: user_velocity
                values: [0.1]
              - entry: distance
                values: ["sin(tt)"]
            """
        )
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    text = str(info.value)
    assert "inputs[0].entry: no entry named 'distanse' takes an input" in text
    assert "'distance'" in text
    assert "takes 2 input value(s), got 1" in text
    assert "inputs[2].values[0]" in text
    assert "unknown name 'tt'" in text


def test_cbp_run_writes_the_orbit_outputs(tmp_path: Path) -> None:
    out = tmp_path / "orbit"
    result = run_cbp(
        "run",
        str(SCENARIOS / "youbot_orbit_case2.yaml"),
        "--set",
        "duration=6",
        "--out",
        str(out),
    )
    assert result.returncode == 0, result.stderr
    metrics = json.loads((out / "metrics.json").read_text())["velocity"]
    for key in (
        "transient_s",
        "distance_error_max_m",
        "view_error_max_deg",
        "roll_max_deg",
        "altitude_margin_min_m",
        "obstacle_margin_min_m",
        "base_travel_m",
        "arm_travel_rad",
        "compute_ms_median",
    ):
        assert key in metrics
    for name in (
        "distance",
        "orientation",
        "roll",
        "altitude",
        "obstacle",
        "velocities",
    ):
        assert (out / f"{name}.png").stat().st_size > 0


def test_objects_that_appear_or_move_reach_the_simulation_and_the_contacts(
    tmp_path: Path,
) -> None:
    """The velocity executor follows ``appear_at`` and ``motion`` as CAT's does.

    Both simulations add and move the objects' bodies; the contact rows' world
    holds them where they are, a moving one measured a tick and the robot's
    stopping time ahead.
    """
    import pybullet as pb

    from cbp.collision import PrimitiveEnvironment
    from cbp.executors.velocity import VelocityLoop
    from cbp.sim.mobile import MobileSimulation

    path = tmp_path / "youbot_contacts.yaml"
    path.write_text(
        textwrap.dedent(
            """
            name: youbot_contacts
            robot: {name: kuka_youbot}
            method: {name: velocity, velocity: {dt: 0.02}}
            simulation: {rate_hz: 500.0}
            duration: 1.0
            tasks:
              - {type: joint_step, name: effort}
            constraints:
              - {type: contact_normals}
              - {type: joint_velocity}
            world:
              objects:
                - {name: wall, shape: box, size: [0.1, 1.0, 1.0],
                   pose: {position: [1.5, 0.0, 0.5]}, appear_at: 0.2}
                - name: crate
                  shape: box
                  size: [0.2, 0.2, 0.2]
                  pose: {position: [-1.5, 0.0, 0.1]}
                  motion: {velocity: [0.0, 0.5, 0.0], start: 0.0, stop: 2.0}
            """
        )
    )
    scenario = load_scenario(path)
    sim = MobileSimulation(
        scenario.robot,
        scenario.spec.world.objects,
        scenario.q0,
        scenario.spec.simulation,
        path.parent,
    )
    try:
        loop = VelocityLoop(scenario, sim)
        for k in range(20):  # 0.4 s
            loop.tick(0.02 * k)
        assert "wall" in sim.scene.object_ids  # added at 0.2 s
        crate = sim.scene.object_ids["crate"]
        y = pb.getBasePositionAndOrientation(crate, physicsClientId=sim.client)[0][1]
        assert y == pytest.approx(0.5 * sim.t, abs=0.01)
    finally:
        sim.close()
    assert any("object 'wall' appeared" in m for _, m in loop.events)
    environment = scenario.world_for_run().environment
    assert isinstance(environment, PrimitiveEnvironment)
    assert [o.name for o in environment.objects] == ["wall", "crate"]
    moving = environment.objects[1]
    np.testing.assert_allclose(moving.velocity, [0.0, 0.5, 0.0])
    # Where it was at the last tick (0.38 s).
    assert moving.placement.translation[1] == pytest.approx(0.5 * 0.38, abs=1e-9)
    assert environment.look_ahead == pytest.approx(
        0.02 + scenario.robot.stopping_time()
    )


def test_the_cameras_are_refused_where_no_map_is_built(tmp_path: Path) -> None:
    """The velocity and kinematic executors would run blind: a located error."""
    path = tmp_path / "orbit_cameras.yaml"
    path.write_text(
        textwrap.dedent(
            f"""\
            name: orbit_cameras
            include: {SCENARIOS / "youbot_orbit_case1.yaml"}
            perception:
              source: depth_camera
              cameras:
                - {{name: head, position: [-0.5, 0.0, 1.5], target: [0.5, 0.0, 0.2]}}
            """
        )
    )
    scenario = load_scenario(path)
    with pytest.raises(ConfigError, match="builds no map from depth cameras"):
        run_velocity(scenario)
    with pytest.raises(ConfigError, match=r"perception\.source"):
        run_kinematic(scenario)
    result = run_cbp("run", str(path), "--out", str(tmp_path / "out"))
    assert result.returncode == 2
    assert f"{path}: perception.source" in result.stderr
    assert not (tmp_path / "out").exists()  # refused before anything ran
