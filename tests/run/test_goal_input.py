"""The goal as a run takes it: rejected samples are said once per episode."""

from __future__ import annotations

import numpy as np

from cbp.goals import LiveGoal
from cbp.run.events import RunLog
from cbp.run.goal_input import GoalInput

RATE = 30.0
START = np.array([0.4, 0.0, 0.4])


def _sent(goal: GoalInput, first: int, last: int) -> None:
    """Send the goal at the samples ``first`` to ``last`` (inclusive)."""
    for k in range(first, last + 1):
        goal.send(k / RATE)


def test_a_bad_goal_held_for_a_second_is_one_event_and_a_count() -> None:
    """30 malformed samples: said at the first, counted when a good one comes."""
    live = LiveGoal(START, np.eye(3), RATE)
    log = RunLog("cat")
    goal = GoalInput(live, None, log)
    _sent(goal, 0, 2)
    live.set(np.array([np.nan, 0.0, 0.4]), np.eye(3))
    _sent(goal, 3, 32)
    kept = goal.goal(32 / RATE)
    assert kept is not None
    np.testing.assert_array_equal(kept.translation, START)
    [(t, said)] = log.events
    assert t == 3 / RATE
    assert said.startswith("goal rejected, previous goal kept: goal: not finite")
    live.set(np.array([0.45, 0.0, 0.4]), np.eye(3))
    _sent(goal, 33, 40)
    assert log.events[1:] == [
        (33 / RATE, "goal accepted again after 30 rejected sample(s) since 0.10 s")
    ]
    assert log.counters == {"rejected_goal_samples": 30}


def test_three_bad_goals_in_a_row_are_one_episode() -> None:
    """Teleop's case: three malformed goals sent in turn, one event, one count."""
    live = LiveGoal(START, np.eye(3), RATE)
    log = RunLog("cat")
    goal = GoalInput(live, None, log)
    _sent(goal, 0, 1)
    bad = (
        (np.array([np.nan, 0.0, 0.4]), np.eye(3)),
        (START, np.zeros((3, 3))),
        (START, np.diag([1.0, 1.0, -1.0])),  # a reflection, not a rotation
    )
    for i, (position, rotation) in enumerate(bad):
        live.set(position, rotation)
        _sent(goal, 2 + 10 * i, 11 + 10 * i)
    live.set(START, np.eye(3))
    _sent(goal, 32, 33)
    messages = [m for _, m in log.events]
    assert len(messages) == 2
    assert messages[0].startswith("goal rejected, previous goal kept: goal: not")
    assert messages[1] == (
        "goal accepted again after 30 rejected sample(s) since 0.07 s"
    )
    assert log.counters["rejected_goal_samples"] == 30


def test_a_run_that_ends_rejecting_keeps_the_count() -> None:
    """No good goal after the bad ones: one event, and the count in the counters."""
    live = LiveGoal(START, np.eye(3), RATE)
    log = RunLog("ik")
    goal = GoalInput(live, None, log)
    goal.send(0.0)
    live.set(START, np.zeros((3, 3)))
    _sent(goal, 1, 44)
    assert len(log.events) == 1
    assert log.counters["rejected_goal_samples"] == 44
