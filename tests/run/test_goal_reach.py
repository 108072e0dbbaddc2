"""A scenario's goal beyond the arm's reach is said to be, as it is taken."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cbp.run.events import RunLog
from cbp.run.goal_input import GoalInput
from cbp.scenario import load_scenario
from cbp.scenario.reach import Reach

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


class _Line:
    """A goal out along x at 1 m/s to x = 1 m at 1 s, then back; sampled at 100 Hz."""

    rate_hz = 100.0

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        return np.array([1.0 - abs(1.0 - t), 0.0, 0.0]), np.eye(3)


def test_a_goal_leaving_and_coming_back_within_reach_is_said_twice() -> None:
    """One event out (with the distances), one back; none while it stays out."""
    log = RunLog("cat")
    goals = GoalInput(_Line(), None, log, reach=Reach(np.zeros(3), 0.5))
    for t in np.arange(0.0, 2.0, 0.01):
        goals.send(float(t))
    (out, said), (back, again) = log.events
    assert 0.5 < out < 0.52
    assert said.startswith("goal out of reach: 0.51 m from the arm's first joint")
    assert said.endswith(
        "(0.50 m, its links' lengths between their joints' axes); the arm stops "
        "short of it"
    )
    assert 1.49 < back < 1.51
    assert again == "goal within the arm's reach again"


def test_an_operator_goal_is_clamped_not_said_out_of_reach() -> None:
    """With bounds (a live goal), the clamp's own event speaks; reach is not said twice."""
    scenario = load_scenario(SCENARIOS / "cat_free_step.yaml")
    from cbp.run.goal_input import GoalBounds

    log = RunLog("cat")
    goals = GoalInput(
        _Line(), None, log, bounds=GoalBounds.of(scenario), reach=scenario.reach()
    )
    goals.send(1.0)  # 1 m ahead of the first joint's x: beyond the Panda's 0.86 m
    assert [m.split(":")[0] for _, m in log.events] == ["goal clamped"]
