"""The CAT outcomes of the paper's Sec. VI, measured on our scenes (slow).

Each scene runs once per perception source; the assertions read the metrics
that ``cbp run`` writes. Where our result differs from the paper's, the test
says so and asserts what we measure instead (docs/cat_scenes.md explains why).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cbp.executors.cat import run_cat
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario
from cbp.trace import Trace

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"

pytestmark = pytest.mark.slow


@cache
def _run(
    scene: str,
    source: str = "ground_truth",
    clock: str = "virtual",
    more: tuple[tuple[str, str], ...] = (),
) -> tuple[Trace, dict[str, Any]]:
    """One run of a paper scene, by default on the virtual clock.

    Outcomes are asserted on the virtual clock, where they do not depend on the
    machine's load: on the wall clock of a loaded 2-core machine the retreat
    with the cameras was held at the middle board's hidden front edge for 2-9 s
    rather than 1.5 s, and once not reached within the scene's 12 s (0 N in
    every run). Only the test of steps per period reads the wall clock.
    """
    scenario = load_scenario(
        SCENARIOS / f"cat_{scene}.yaml",
        overrides={
            "perception.source": source,
            "method.cat.timing.clock": clock,
            **dict(more),
        },
    )
    trace = run_cat(scenario)
    return trace, run_metrics(trace)


@pytest.mark.parametrize("source", ["ground_truth", "depth_camera"])
@pytest.mark.parametrize("scene", ["free_step", "free_continuous"])
def test_free_space_is_reached(scene: str, source: str) -> None:
    _, m = _run(scene, source)
    assert m["reached"], m
    assert m["peak_contact_force_n"] == 0.0
    assert m["response_time_s"] < 0.3


def test_free_space_continuous_input_is_tracked_closely() -> None:
    """Continuous input: done within half a second of the goal's last move."""
    _, m = _run("free_continuous")
    assert m["total_time_s"] < 1.5 + 0.5


def test_boards_slides_over_without_touching() -> None:
    trace, m = _run("boards")
    assert m["reached"], m
    assert m["peak_contact_force_n"] == 0.0
    assert m["min_clearance_m"] > 0.0
    # It went over: the hand rose above the boards' tops on the way.
    assert trace.ee_position[:, 2].max() > 0.15 + 0.02


def test_local_minimum_stops_in_front_of_the_wall() -> None:
    trace, m = _run("local_minimum")
    assert not m["reached"]
    assert m["peak_contact_force_n"] == 0.0
    assert m["min_clearance_m"] > 0.0
    assert trace.ee_position[-1, 1] < -0.01  # still on the start side (wall at y = 0)


def test_unreachable_goal_tracks_the_workspace_edge_then_reaches() -> None:
    """While the goal moves sideways out of reach, the hand follows it sideways."""
    trace, m = _run("unreachable")
    assert m["reached"], m
    outside = (trace.t >= 2.5) & (trace.t <= 4.0)
    goal_travel = np.ptp(trace.goal_position[outside, 1])
    hand_travel = np.ptp(trace.ee_position[outside, 1])
    assert hand_travel > 0.5 * goal_travel


@pytest.mark.parametrize("scene", ["shelf_reach", "shelf_retreat"])
def test_shelf_reach_and_retreat_without_contact(scene: str) -> None:
    _, m = _run(scene)
    assert m["reached"], m
    assert m["peak_contact_force_n"] == 0.0
    assert m["min_clearance_m"] > 0.0


def test_wrist_limit_stays_within_limits_and_out_of_contact() -> None:
    """Safe, but (unlike the paper's PR2) not reached: see the xfail below."""
    trace, m = _run("wrist_limit")
    scenario = load_scenario(SCENARIOS / "cat_wrist_limit.yaml")
    robot = scenario.robot
    assert np.all(trace.q >= robot.lower_limits - 1e-3)
    assert np.all(trace.q <= robot.upper_limits + 1e-3)
    assert m["peak_contact_force_n"] == 0.0


@pytest.mark.xfail(
    strict=True,
    reason="on the Panda, turning the hand up needs a 1.6 rad reconfiguration of "
    "joints 1, 3 and 5 that a local method does not find; the PR2 does it with "
    "its forearm roll alone (docs/cat_scenes.md)",
)
def test_wrist_limit_is_reached() -> None:
    _, m = _run("wrist_limit")
    assert m["reached"]


def test_many_steps_per_period_on_boards_and_shelf() -> None:
    """More QP steps per 33 ms period than the paper's 15-20.

    As the paper's CAT steps, until the budget is spent or the motion is still
    (``reach_periods: 0``, ``converged_step: 1e-5``): by default a period ends
    once its path is long enough or its steps fall below 5e-5 rad, and a
    wall-clock run in CI then had no period that used its whole budget.
    """
    paper = (("method.cat.reach_periods", "0"), ("method.cat.converged_step", "1e-5"))
    for scene in ("boards", "shelf_reach"):
        _, m = _run(scene, clock="wall", more=paper)
        assert m["steps_per_full_period_median"] > 20, (scene, m)


@pytest.mark.parametrize(
    "scene",
    [
        "boards",
        "local_minimum",
        "wrist_limit",
        "unreachable",
        "shelf_reach",
        "shelf_retreat",
    ],
)
def test_the_cameras_map_keeps_every_scene_free_of_contact(scene: str) -> None:
    """Unseen space counts as an obstacle: no contact, outcomes as declared."""
    _, camera = _run(scene, "depth_camera")
    _, declared = _run(scene)
    assert camera["peak_contact_force_n"] == 0.0, camera
    assert camera["reached"] == declared["reached"]


# The shelf retreat seen only by the head camera and a wrist camera mounted low on
# the hand: the middle board's underside, which the arm passes on its way out, is
# hidden from both (by the arm and by the board itself).
FEW_CAMERAS = (
    "[{name: head, position: [-0.35, 0.0, 1.15], target: [0.55, 0.0, 0.15]},"
    " {name: wrist, parent: end_effector, offset: {position: [0.035, 0.0, 0.02],"
    " rpy_deg: [0.0, 25.0, 0.0]}, width: 160, height: 120, fov_deg: 80.0,"
    " near: 0.05, far: 1.5}]"
)


@pytest.mark.parametrize("robot_space", ["held", "nearby"])
def test_an_obstacle_no_camera_sees_is_never_entered(robot_space: str) -> None:
    """The robot frees only the space it has held, so it stops short of the board.

    The run says that unseen space holds the arm, and beside which links.

    With ``robot_space: nearby`` (the old behaviour) every frame freed a few centimetres
    of unseen space around the arm, which then moved into them, frame after
    frame, and pressed the board (measured 177 N): the test shows that hazard,
    with exact frames (with the cameras' noise on, this run happened to reach
    at 0 N). Virtual time, so each run is the same.
    """
    exact = FEW_CAMERAS.replace("far: 1.5}", "far: 1.5, noise: {enabled: false}}")
    exact = exact.replace(
        "target: [0.55, 0.0, 0.15]}",
        "target: [0.55, 0.0, 0.15], noise: {enabled: false}}",
    )
    scenario = load_scenario(
        SCENARIOS / "cat_shelf_retreat.yaml",
        overrides={
            "perception.source": "depth_camera",
            "perception.cameras": exact,
            "perception.robot_space": robot_space,
            "method.cat.timing.clock": "virtual",
        },
    )
    trace = run_cat(scenario)
    m = run_metrics(trace)
    if robot_space == "held":
        assert m["peak_contact_force_n"] == 0.0, m
        assert not m["reached"]  # the way out lies in space nothing has seen
        # ... and the run says so.
        said = [e for _, e in trace.events if "held by space no camera" in e]
        assert said, trace.events
        assert "panda_link6" in said[0]
    else:
        assert m["peak_contact_force_n"] > 50.0, m


def test_with_noisy_cameras_the_boards_are_passed_without_touching() -> None:
    """With the cameras' noise model on (its default), the boards: 0 N, reached.

    Virtual clock, so the run does not depend on the machine's load;
    docs/noise.md has the eight scenes.
    """
    scenario = load_scenario(
        SCENARIOS / "cat_boards.yaml",
        overrides={
            "perception.source": "depth_camera",
            "method.cat.timing.clock": "virtual",
        },
    )
    assert all(c.noise.enabled for c in scenario.spec.perception.all_cameras)
    m = run_metrics(run_cat(scenario))
    assert m["reached"], m
    assert m["peak_contact_force_n"] == 0.0
