"""The method table: every periodic method gives its planner to other loops."""

from __future__ import annotations

import dataclasses

import pytest

from cbp.executors import make_planner
from cbp.methods import METHODS, PERIODIC, MethodSpec
from cbp.run import build_run
from cbp.run.loop import run_loop
from cbp.scenario import load_scenario
from tests.executors.test_cat import SCENARIOS


def test_periodic_methods_are_the_trajectory_loop_planners() -> None:
    """The periodic rows are CAT, IK, MP and hybrid; JT has no planner."""
    assert PERIODIC == ("cat", "ik", "mp", "hybrid")
    scenario = load_scenario(SCENARIOS / "cat_boards.yaml")
    with pytest.raises(ValueError, match="no per-period planner"):
        make_planner("jt", None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="no per-period planner"):
        scenario.spec.method.timing("jt")


def test_the_method_section_has_one_settings_field_per_method() -> None:
    """MethodSpec is written once, and its fields are the table's rows."""
    fields = {f.name: f.type for f in dataclasses.fields(MethodSpec)}
    assert list(fields) == ["name", *METHODS]
    spec = MethodSpec()
    for name, row in METHODS.items():
        assert isinstance(getattr(spec, name), row.settings)


def test_methods_that_plan_with_ompl_run_in_a_fresh_process() -> None:
    """The table says which methods seed OMPL once per process: MP and hybrid."""
    assert {n for n, m in METHODS.items() if m.fresh_process} == {"mp", "hybrid"}


def test_every_method_has_its_own_colour() -> None:
    """One colour per method, for every figure and page."""
    colours = [m.colour for m in METHODS.values()]
    assert len(set(colours)) == len(colours)


@pytest.mark.parametrize("method", PERIODIC)
def test_make_planner_gives_a_planner_the_trajectory_loop_runs(method: str) -> None:
    """A short run of the boards with the table's planner, as cbp teleop runs it."""
    scenario = load_scenario(
        SCENARIOS / "cat_boards.yaml",
        overrides={"method.name": method, "duration": "0.5"},
    )
    parts = build_run(scenario, method=method, needs_world=True)
    planner = make_planner(method, parts)
    assert type(planner).__name__.lower().startswith(method)
    trace = run_loop(parts, planner, scenario.spec.method.timing("cat"))
    assert trace.t[-1] == pytest.approx(0.5, abs=0.05)
    assert trace.aborted is None
    assert not any("robot held" in message for _, message in trace.events), trace.events
