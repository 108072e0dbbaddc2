"""The kinematic executor: tracking, and safe holds on bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from cbp.executors.kinematic import run_kinematic
from cbp.scenario import load_scenario

REACH = Path(__file__).resolve().parents[2] / "scenarios" / "panda_reach.yaml"


def test_panda_reach_tracks_the_goal_within_limits() -> None:
    """The hand ends on the last keyframe; joints never leave their limits."""
    scenario = load_scenario(REACH)
    trace = run_kinematic(scenario)
    robot = scenario.robot
    assert trace.position_error[-1] < 1e-3
    assert trace.rotation_error[-1] < np.deg2rad(0.5)
    bq = robot.bounded_q
    assert np.all(trace.q[:, bq] >= robot.lower_limits[bq] - 1e-9)
    assert np.all(trace.q[:, bq] <= robot.upper_limits[bq] + 1e-9)
    steps = np.diff(trace.q, axis=0) / scenario.spec.method.kinematic.dt
    assert np.all(np.abs(steps) <= 0.5 * robot.velocity_limits + 1e-9)
    assert trace.events == []


def test_nan_goal_is_ignored_and_the_loop_goes_on(monkeypatch) -> None:
    """A NaN goal is rejected and recorded; the previous goal stays in force."""
    scenario = load_scenario(REACH)
    stream_cls = type(scenario.goal_stream())
    original = stream_cls.sample

    def sample(self, t):  # type: ignore[no-untyped-def]
        if 1.0 <= t < 1.2:
            return np.array([np.nan, 0.0, 0.0]), np.eye(3)
        return original(self, t)

    monkeypatch.setattr(stream_cls, "sample", sample)
    trace = run_kinematic(scenario)
    assert any("goal rejected" in message for _, message in trace.events)
    assert np.all(np.isfinite(trace.q))
    assert trace.position_error[-1] < 1e-3


def test_conflicting_hard_entries_hold_what_they_conflict_on(tmp_path: Path) -> None:
    """Two hard postures pull joint 1 both ways: the engine holds it, once.

    The demands are scaled to zero; the goal task moves the other joints.
    """
    text = REACH.read_text().replace(
        "  - type: posture\n    weight: 1.0e-4\n    gain: 0.1\n",
        "  - type: posture\n    name: left\n    priority: hard\n    gain: 1.0\n"
        "    params: {target: {panda_joint1: 2.5}, joints: [panda_joint1]}\n"
        "  - type: posture\n    name: right\n    priority: hard\n    gain: 1.0\n"
        "    params: {target: {panda_joint1: -2.5}, joints: [panda_joint1]}\n",
    )
    path = tmp_path / "conflict.yaml"
    path.write_text(text)
    scenario = load_scenario(path)
    trace = run_kinematic(scenario)
    assert [e for _, e in trace.events] == [
        "QP eased: 2 row(s) of left, right asked for more motion than the limits "
        "allow together: held (k = 0: no further, no change)",
        "QP eased 600 more time(s) from 0.00 to 6.00 s",
    ]
    np.testing.assert_allclose(trace.q[:, 0], trace.q[0, 0], atol=1e-12)
    assert np.ptp(trace.q[:, 1:], axis=0).max() > 0.1


def test_cbp_run_writes_its_outputs(tmp_path: Path) -> None:
    """Cbp run writes report, metrics, trace and plot."""
    result = subprocess.run(
        [sys.executable, "-m", "cbp", "run", str(REACH), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    for name in ("report.md", "metrics.json", "trace.csv", "tracking.png"):
        assert (tmp_path / name).is_file()
    metrics = json.loads((tmp_path / "metrics.json").read_text())["kinematic"]
    assert metrics["reached"] is True
    assert metrics["max_joint_limit_violation_rad"] == 0.0
