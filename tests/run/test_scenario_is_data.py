# SPDX-License-Identifier: Apache-2.0
"""A scenario is data: the same object runs twice with identical results."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cbp.executors import load_executor
from cbp.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@pytest.mark.parametrize(
    ("file", "method"),
    [("cat_appearing_obstacle.yaml", "cat"), ("cat_boards.yaml", "kinematic")],
)
def test_one_scenario_runs_twice_with_identical_traces(file: str, method: str) -> None:
    """Each run binds its own plugins and world: nothing leaks from the first."""
    scenario = load_scenario(
        SCENARIOS / file,
        overrides={"duration": "2.0", "method.cat.timing.clock": "virtual"},
    )
    run = load_executor(method)
    first, second = run(scenario, False), run(scenario, False)
    assert len(first.t) == len(second.t) > 10
    np.testing.assert_array_equal(first.q, second.q)
    np.testing.assert_array_equal(first.ee_position, second.ee_position)
    assert first.events == second.events


def test_each_run_binds_its_own_plugins_and_world() -> None:
    """Two runs of one scenario share no plugin and no world, with it or each other."""
    from cbp.run import build_run

    scenario = load_scenario(SCENARIOS / "cat_appearing_obstacle.yaml")
    runs = [build_run(scenario, method="cat", clock="virtual") for _ in range(2)]
    try:
        bindings = [scenario, *(r.scenario for r in runs)]
        plugins = [{id(e.plugin) for e in s.entries} for s in bindings]
        assert all(len(p) == len(scenario.entries) for p in plugins)
        assert not plugins[0] & plugins[1]
        assert not plugins[0] & plugins[2]
        assert not plugins[1] & plugins[2]
        worlds = [scenario.world, *(r.world for r in runs)]
        assert all(w is not None for w in worlds)
        assert len({id(w) for w in worlds}) == 3
        assert all(r.world is r.scenario.world for r in runs)
    finally:
        for r in runs:
            r.close()
