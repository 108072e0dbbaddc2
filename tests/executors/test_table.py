"""The executor table: every periodic executor gives its planner to other loops."""

from __future__ import annotations

import pytest

from cbp.executors import EXECUTORS, PERIODIC
from cbp.executors.simulated import SimulatedRun
from cbp.scenario import load_scenario
from tests.executors.test_cat import SCENARIOS


def test_periodic_executors_are_the_trajectory_loop_planners() -> None:
    assert PERIODIC == ("cat", "ik", "mp", "hybrid")
    with pytest.raises(ValueError, match="no per-period planner"):
        EXECUTORS["jt"].make_planner(None, None)  # type: ignore[arg-type]


@pytest.mark.parametrize("method", PERIODIC)
def test_make_planner_gives_a_planner_the_trajectory_loop_runs(method: str) -> None:
    """A short run of the boards with the table's planner, as cbp teleop runs it."""
    from cbp.executors.settings import CatSettings
    from cbp.executors.trajectory import run_trajectory_executor

    scenario = load_scenario(
        SCENARIOS / "cat_boards.yaml",
        overrides={"method.name": method, "duration": "0.5"},
    )
    run = SimulatedRun(scenario, method, needs_world=True)
    planner = EXECUTORS[method].make_planner(scenario, run)
    assert type(planner).__name__.lower().startswith(method)
    try:
        timing = scenario.spec.method.settings(CatSettings).timing
        trace = run_trajectory_executor(run, planner, timing)
    finally:
        close = getattr(planner, "close", None)
        if close is not None:
            close()
    assert trace.t[-1] == pytest.approx(0.5, abs=0.05)
    assert trace.aborted is None
    assert not any("robot held" in message for _, message in trace.events), trace.events
