"""An arm crushed between two boxes says so: forced off its command, not tracking."""

from __future__ import annotations

from pathlib import Path

from cbp.executors.cat import run_cat
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _pincer(tmp_path: Path) -> Path:
    """Two boxes close on the still hand at 12 cm/s each, until they overlap."""
    boxes = [
        f"    - {{name: {name}, shape: box, size: [0.3, 0.1, 0.3], "
        f"pose: {{position: [0.307, {y}, 0.55]}}, "
        f"motion: {{velocity: [0.0, {v}, 0.0], start: 0.5, stop: 3.0}}}}\n"
        for name, y, v in (("left", 0.3, -0.12), ("right", -0.3, 0.12))
    ]
    path = tmp_path / "pincer.yaml"
    path.write_text(
        f"name: pincer\ninclude: {SCENARIOS}/configs/cat.yaml\n"
        "robot: {name: franka_panda}\nduration: 3.5\n"
        "goal: {type: keyframes, keyframes: "
        "[{t: 0.0, pose: {position: [0.307, 0.0, 0.59], rpy_deg: [180, 0, 0]}}]}\n"
        "world:\n  objects:\n" + "".join(boxes)
    )
    return path


def test_a_crushed_arm_is_said_to_be_forced_off_its_command(tmp_path: Path) -> None:
    """The event names the joint; the metric and the report's sentence agree."""
    scenario = load_scenario(
        _pincer(tmp_path), overrides={"method.cat.timing.clock": "virtual"}
    )
    trace = run_cat(scenario)
    forced = [m for _, m in trace.events if m.startswith("the arm is forced")]
    assert len(forced) == 1, trace.events
    assert "off its command at panda_joint" in forced[0]
    assert forced[0].endswith("by what it touches: pressed harder than its joints hold")
    assert run_metrics(trace)["max_joint_tracking_error"] > 0.1


def test_an_arm_that_tracks_is_not_said_to_be_forced() -> None:
    """The free step, fast motions and all: within the controller's tracking."""
    scenario = load_scenario(
        SCENARIOS / "cat_free_step.yaml",
        overrides={"method.cat.timing.clock": "virtual"},
    )
    trace = run_cat(scenario)
    assert not any("forced" in m for _, m in trace.events)
    assert run_metrics(trace)["max_joint_tracking_error"] < 0.05
