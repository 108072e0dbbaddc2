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
def _run(scene: str, source: str = "ground_truth") -> tuple[Trace, dict[str, Any]]:
    scenario = load_scenario(
        SCENARIOS / f"cat_{scene}.yaml", overrides={"perception.source": source}
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
    """More QP steps per 33 ms period than the paper's 15-20."""
    for scene in ("boards", "shelf_reach"):
        _, m = _run(scene)
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
    """Unseen space counts as an obstacle: no contact, outcomes as declared.

    Except the shelf retreat's: with the cameras the wrist camera's housing is a
    robot shape, and whether it passes the middle board's front edge (4-7 mm
    clear) or stops at it depends on the steps each period holds (wall clock):
    measured reached in 2 of 3 runs, stopped in the third, 0 N in all.
    """
    _, camera = _run(scene, "depth_camera")
    _, declared = _run(scene)
    assert camera["peak_contact_force_n"] == 0.0, camera
    if scene != "shelf_retreat":
        assert camera["reached"] == declared["reached"]
