"""timing.clock: virtual: the same scenario gives the same run on any load."""

from __future__ import annotations

import multiprocessing
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cbp.executors.cat import run_cat
from cbp.methods.settings import VirtualCosts
from cbp.metrics import run_metrics
from cbp.run import budget as clock
from cbp.run.budget import VirtualBudget, WallBudget
from cbp.scenario import load_scenario

BOARDS = Path(__file__).resolve().parents[2] / "scenarios" / "cat_boards.yaml"


def _virtual_run(duration: float = 3.0) -> tuple[dict[str, Any], np.ndarray]:
    scenario = load_scenario(
        BOARDS,
        overrides={
            "method.cat.timing.clock": "virtual",
            "duration": str(duration),
            # Steps until the budget is spent, so that full periods are counted.
            "method.cat.reach_periods": "0",
        },
    )
    trace = run_cat(scenario)
    return run_metrics(trace, scenario.robot), trace.q


def test_budgets_count_wall_time_or_charged_work() -> None:
    costs = VirtualCosts()
    virtual = VirtualBudget(0.001, costs)
    virtual.charge("qp_step", 6)
    assert not virtual.spent()
    assert virtual.elapsed() == pytest.approx(6 * costs.qp_step)
    virtual.charge("collision_check")
    assert not virtual.spent()
    virtual.charge("qp_step")  # 7 steps and a check: 1.026 ms
    assert virtual.spent()
    wall = WallBudget(10.0)
    wall.charge("qp_step", 10**6)  # wall time counts itself
    assert not wall.spent()
    assert WallBudget(0.0).spent()


def test_two_virtual_runs_are_identical() -> None:
    first, q1 = _virtual_run()
    second, q2 = _virtual_run()
    assert first == second  # every metric, compute per period included
    np.testing.assert_array_equal(q1, q2)
    assert first["steps_per_full_period_median"] == pytest.approx(
        round(0.8 / 30 / VirtualCosts().qp_step), abs=1
    )


def _spin(stop: Any) -> None:
    x = 0
    while not stop.is_set():
        x += 1


@pytest.mark.slow
def test_a_virtual_run_under_load_matches_one_without() -> None:
    quiet, q_quiet = _virtual_run()
    stop = multiprocessing.Event()
    hogs = [multiprocessing.Process(target=_spin, args=(stop,)) for _ in range(3)]
    for hog in hogs:
        hog.start()
    try:
        loaded, q_loaded = _virtual_run()
    finally:
        stop.set()
        for hog in hogs:
            hog.join()
    assert loaded == quiet
    np.testing.assert_array_equal(q_loaded, q_quiet)


def test_a_wall_budget_begins_no_unit_that_would_end_past_it(monkeypatch) -> None:
    """The last unit's cost counts: work that would overrun the budget is not begun."""
    now = [100.0]
    monkeypatch.setattr(clock.time, "perf_counter", lambda: now[0])
    budget = clock.WallBudget(0.1)
    now[0] += 0.03  # a first step of 30 ms
    budget.charge("qp_step")
    assert not budget.spent()  # 30 ms used, 30 more end at 60
    now[0] += 0.03
    budget.charge("qp_step")
    assert not budget.spent()  # the next would end at 90 ms
    now[0] += 0.03
    budget.charge("qp_step")
    assert budget.spent()  # the next would end at 120 ms: not begun
    assert budget.elapsed() == pytest.approx(0.09)
    assert budget.left() == pytest.approx(0.01)
