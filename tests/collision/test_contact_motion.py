"""The engine with contact constraints: pushed into a box, the hand stops and slides."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cbp.executors.kinematic import run_kinematic
from cbp.scenario import load_scenario
from cbp.state import RobotState

SCENARIO = Path(__file__).parents[2] / "scenarios" / "panda_push_box.yaml"


@pytest.fixture(scope="module")
def run():
    scenario = load_scenario(SCENARIO)
    return scenario, run_kinematic(scenario)


def test_penetration_stays_under_the_tolerance_while_the_goal_is_inside(run) -> None:
    scenario, trace = run
    tolerance = scenario.spec.collision.penetration_tolerance
    assert trace.step_penetration is not None  # the steps were validated
    assert trace.step_penetration.max() <= tolerance
    inside = (trace.t >= 1.5) & (trace.t <= 2.5)
    # The goal is 12 cm or more below where the hand stopped: it did not follow.
    assert np.all(trace.position_error[inside] > 0.1)
    assert np.ptp(trace.ee_position[inside, 2]) < 1e-3


def test_the_hand_slides_along_the_face_when_the_goal_moves_sideways(run) -> None:
    _, trace = run
    stopped_z = trace.ee_position[trace.t <= 2.5, 2][-1]
    end = trace.ee_position[-1]
    assert end[1] == pytest.approx(0.15, abs=5e-3)
    assert end[2] == pytest.approx(stopped_z, abs=2e-3)
    assert not trace.events


def test_a_rejected_step_constrains_the_retry(robots) -> None:
    scenario = load_scenario(SCENARIO)
    world = scenario.world_for_run()
    robot = scenario.robot
    q = robot.home()
    ok = world.check(q)
    assert ok.accepted
    # Far into the box: rejected, and its contacts come back once at q.
    deep = q.copy()
    deep[1] += 0.5  # shoulder forward: the fingers go 5 cm into the box
    bad = world.check(deep)
    assert not bad.accepted
    assert bad.penetration > scenario.spec.collision.penetration_tolerance
    carried = bad.contacts.select(bad.contacts.distance < 0)
    world.carry_over(carried)
    state = RobotState(robot, q)
    with_carried = world.contacts(state)
    assert len(with_carried) == len(world.contacts(state)) + len(carried)
