"""The CAT executor in the simulator: runs, bad input, failures, outputs."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np

from cbp.engine import Engine
from cbp.errors import SolveError
from cbp.executors import make_planner
from cbp.executors.cat import REACHED_NOTE, run_cat
from cbp.goals import LiveGoal, write_recorded
from cbp.metrics import run_metrics
from cbp.run import RunListener, build_run, run_loop
from tests.conftest import load_virtual, run_cbp

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"
DOWN = np.diag([1.0, -1.0, -1.0])


def test_free_space_step_reaches_the_goal_without_contact() -> None:
    """A short free-space step: reached, in time, many QP steps per period."""
    scenario = load_virtual(
        SCENARIOS / "cat_free_step.yaml", overrides={"duration": "2.2"}
    )
    trace = run_cat(scenario)
    m = run_metrics(trace)
    assert m["reached"], m
    assert m["peak_contact_force_n"] == 0.0
    assert m["response_time_s"] < 0.3
    assert m["steps_per_period_median"] > 5
    # Continuity: commanded positions never jump between samples.
    assert np.max(np.abs(np.diff(trace.q_cmd, axis=0))) < 0.02
    assert all(p.spliced or p.missed or p.note for p in trace.periods)


def test_a_period_ends_once_its_path_reaches_past_the_next_period() -> None:
    """``reach_periods``: the steps past that reach are saved, the motion is not.

    The free-space step on the virtual clock, stepping until the budget is
    spent (0, the paper's CAT) and by default: the arm moves the same to
    within 0.1 mrad, with at most 70 % of the steps (63 % measured).
    """
    traces = [
        run_cat(
            load_virtual(
                SCENARIOS / "cat_free_step.yaml",
                overrides={"duration": "2.0", "method.cat.reach_periods": reach},
            )
        )
        for reach in ("0", "4")
    ]
    full, reaching = traces
    n = min(len(full.q), len(reaching.q))
    assert np.max(np.abs(full.q[:n] - reaching.q[:n])) < 1e-4
    steps = [sum(p.steps for p in trace.periods) for trace in traces]
    assert steps[1] < 0.7 * steps[0], steps
    assert any(p.note == REACHED_NOTE for p in reaching.periods)
    assert not any(p.note == REACHED_NOTE for p in full.periods)


def _scenario_with_goal_file(tmp_path: Path, goal: str, extra: str = "") -> Path:
    path = tmp_path / "s.yaml"
    path.write_text(
        textwrap.dedent(
            f"""\
            name: bad_goal
            include: {SCENARIOS / "configs" / "cat.yaml"}
            robot: {{name: franka_panda}}
            duration: 2.0
            goal: {{type: recorded, file: {goal}}}
            """
        )
        + extra
    )
    return path


def test_nan_goal_keeps_the_previous_goal_and_says_so_once() -> None:
    """An operator's NaN goal held for a while is rejected: one event, one count.

    A recording cannot hold one (its cells are checked at load), so the goal
    is an operator's, set as each trajectory is commanded in simulated time.
    """
    scenario = load_virtual(SCENARIOS / "cat_free_step.yaml", {"duration": "1.5"})
    live = LiveGoal(np.array([0.307, 0.0, 0.59]), DOWN)
    parts = build_run(scenario, method="cat", goal=live, clock="virtual")

    def operator(t: float) -> None:
        if 0.3 <= t < 0.5:  # a glitch of the input device
            live.set(np.array([np.nan, 0.15, 0.45]), DOWN)
        elif t >= 0.5:
            live.set(np.array([0.45, 0.15, 0.45]), DOWN)

    class Operator(RunListener):
        def commanded(self, t: float) -> None:
            operator(t)

    parts.log.listeners.append(Operator())
    trace = run_loop(
        parts, make_planner("cat", parts), scenario.spec.method.timing("cat")
    )
    rejected = [m for _, m in trace.events if m.startswith("goal rejected")]
    assert len(rejected) == 1
    [again] = [m for _, m in trace.events if m.startswith("goal accepted again")]
    count = trace.counters["rejected_goal_samples"]
    assert count >= 5
    assert again.startswith(f"goal accepted again after {count:g} rejected sample")
    assert np.all(np.isfinite(trace.q))
    assert np.all(np.isfinite(trace.goal_position))  # the rejected goal is not in it
    assert run_metrics(trace)["reached"]


def test_failed_qp_holds_the_last_safe_trajectory(tmp_path: Path, monkeypatch) -> None:
    """Every QP fails (injected): the arm stays where its last trajectory was.

    Here: at rest at the start. Each failure is an event, and the loop keeps
    running.
    """

    def infeasible(self, q, dt, v=None):  # type: ignore[no-untyped-def]
        raise SolveError("injected: the hard entries cannot all be met")

    monkeypatch.setattr(Engine, "step", infeasible)
    times = np.array([0.0, 2.0])
    write_recorded(
        tmp_path / "goal.csv",
        times,
        np.array([[0.6, 0.2, 0.3]] * 2),
        np.array([DOWN] * 2),
    )
    scenario = load_virtual(_scenario_with_goal_file(tmp_path, "goal.csv"))
    trace = run_cat(scenario)
    failures = [m for _, m in trace.events if m.startswith("QP step failed")]
    assert len(failures) >= 50
    assert trace.aborted is None  # a failed solve is not a fault
    np.testing.assert_allclose(trace.q[-1], scenario.q0, atol=1e-3)
    assert len(trace.periods) >= 55


def test_cbp_run_writes_trace_metrics_and_plots(tmp_path: Path) -> None:
    """The command line: trace.csv, metrics.json (under the method's name), PNGs."""
    out = tmp_path / "out"
    result = run_cbp(
        "run",
        str(SCENARIOS / "cat_free_step.yaml"),
        "--method",
        "cat",
        "--set",
        "duration=1.0",
        "--out",
        str(out),
    )
    assert result.returncode == 0, result.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    keys = {
        "reached",
        "response_time_s",
        "total_time_s",
        "final_position_error_m",
        "final_orientation_error_rad",
        "peak_contact_force_n",
        "contact_duration_s",
        "max_penetration_m",
        "min_clearance_m",
        "steps_per_period_median",
        "compute_ms_per_period_median",
        "deadline_misses",
    }
    assert keys <= set(metrics["cat"])
    header = (out / "trace.csv").read_text().splitlines()[0].split(",")
    assert {"t", "goal_x", "ee_qw", "q_panda_joint1", "contact_force"} <= set(header)
    for name in ("tracking.png", "errors.png", "contact_force.png", "report.md"):
        assert (out / name).stat().st_size > 0
    bad = run_cbp("run", str(SCENARIOS / "cat_free_step.yaml"), "--method", "catt")
    assert bad.returncode == 2
    assert "'cat'" in bad.stderr


def test_when_one_step_fits_a_period_the_steps_stretch_to_cover_it() -> None:
    """A QP step that costs most of the budget: the path still spans the period.

    On the virtual clock, one step's cost set to 20 ms of the 27 ms budget:
    two steps fit a 33 ms period. At ``step_dt`` (10 ms here) their path
    spans 20 ms, and the arm, stopped at the path's end each period, moves
    at 60 % of its speed at most; stretched, the first step spans the
    period. The hand's steps are clipped loosely here, so that the velocity
    bounds, which follow the step's duration, are what limits it.
    """
    tasks = (
        "[{type: goal_pose, weight: [1.0, 1.0, 1.0, 0.3, 0.3, 0.3],"
        " params: {max_step_translation: 0.05, max_step_rotation: 0.5}},"
        " {type: joint_step, weight: 1.0e-3}]"
    )
    reached = {}
    for stretch in ("1.0", "3.0"):
        scenario = load_virtual(
            SCENARIOS / "cat_free_step.yaml",
            {
                "method.cat.step_dt": "0.01",
                "method.cat.max_step_stretch": stretch,
                "method.cat.timing.virtual_costs.qp_step": "0.02",
                "tasks": tasks,
            },
        )
        trace = run_cat(scenario)
        m = run_metrics(trace)
        assert m["peak_contact_force_n"] == 0.0
        assert all(p.steps <= 2 for p in trace.periods)
        reached[stretch] = m["total_time_s"]
    assert reached["3.0"] is not None
    assert reached["1.0"] is None or reached["3.0"] < 0.8 * reached["1.0"], reached
