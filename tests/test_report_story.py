"""The report tells what happened: a sentence per method and a picture of the scene."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cbp.cli import main
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario
from cbp.story import plot_scene, run_sentence
from cbp.trace import PeriodRecord, Trace

BOARDS = Path(__file__).resolve().parents[1] / "scenarios" / "cat_boards.yaml"


def _trace(
    end: tuple[float, float, float],
    force: float = 0.0,
    periods: list[PeriodRecord] | None = None,
    events: list[tuple[float, str]] | None = None,
) -> Trace:
    """A straight hand path from (0.5, -0.4, 0.15) toward ``end``; goal at y = 0.4."""
    m = 101
    t = np.linspace(0.0, 5.0, m)
    start = np.array([0.5, -0.4, 0.15])
    s = np.clip(t / 4.0, 0.0, 1.0)[:, None]
    hand = start + s * (np.asarray(end) - start)
    goal = np.tile([0.5, 0.4, 0.15], (m, 1))
    rotations = np.tile(np.eye(3), (m, 1, 1))
    return Trace(
        method="x",
        t=t,
        q=np.zeros((m, 1)),
        ee_position=hand,
        ee_rotation=rotations,
        goal_position=goal,
        goal_rotation=rotations.copy(),
        goal_change_time=0.0,
        contact_force=np.where(t > 3.0, force, 0.0),
        clearance=np.full(m, 0.012),
        periods=periods or [],
        events=events or [],
    )


def _sentence(trace: Trace) -> str:
    return run_sentence("m", trace, run_metrics(trace))


def test_a_run_that_reaches_says_when_and_how_close() -> None:
    """Reached: the time to reach, no contact, and the closest approach."""
    assert _sentence(_trace((0.5, 0.4, 0.15))) == (
        "**m** reached the goal in 4.0 s without contact, passing 12 mm from the "
        "nearest object."
    )


def test_a_run_that_presses_says_how_hard_and_how_long() -> None:
    """Short and in contact: the distance left, the peak force and its duration."""
    sentence = _sentence(_trace((0.5, 0.0, 0.15), force=40.0))
    assert sentence == (
        "**m** stopped 400 mm short of the goal, pressed against the scene (for "
        "2.0 s with up to 40.0 N)."
    )


def test_a_run_that_holds_gives_its_planners_reason() -> None:
    """Short without contact: the note of the periods in which nothing was planned."""
    periods = [
        PeriodRecord(0.1 * k, 0.1, 1, 0.001, False, k < 10, "")
        if k < 10
        else PeriodRecord(0.1 * k, 0.1, 1, 0.001, False, False, "collision ahead")
        for k in range(50)
    ]
    sentence = _sentence(_trace((0.5, 0.1, 0.15), periods=periods))
    assert sentence == (
        "**m** stopped 300 mm short of the goal, because: collision ahead (all of "
        "its last 30 periods)."
    )


def test_a_run_with_only_events_names_the_last() -> None:
    """Short, no periods (a torque executor): the last event is the reason."""
    sentence = _sentence(_trace((0.5, 0.1, 0.15), events=[(2.0, "goal rejected")]))
    assert sentence.endswith("short of the goal, after: goal rejected.")


def test_the_scene_picture_is_drawn(tmp_path: Path) -> None:
    """scene.png: the boards from above and from the front, with each hand path."""
    scenario = load_scenario(BOARDS)
    path = plot_scene(
        scenario.spec.world.objects,
        {"cat": _trace((0.5, 0.4, 0.15)), "jt": _trace((0.5, 0.0, 0.15))},
        tmp_path / "scene.png",
        "boards",
    )
    assert path.stat().st_size > 10_000


@pytest.mark.slow
def test_the_demo_report_tells_each_methods_story(tmp_path: Path) -> None:
    """The report of `make demo`: a sentence per method, with its reason, and the scene."""
    out = tmp_path / "demo"
    command = ["compare", str(BOARDS), "--methods", "cat,ik,mp,jt", "--out", str(out)]
    main(["-q", *command])
    report = (out / "report.md").read_text()
    assert "- **cat** reached the goal in " in report
    assert "- **mp** reached the goal in " in report
    assert "- **ik** stopped " in report
    assert "short of the goal, because: collision ahead" in report
    assert "- **jt** stopped " in report
    assert "short of the goal, pressed against the scene" in report
    assert "![the scene, the goal's path and each method's hand path](scene.png)" in (
        report
    )
    assert (out / "scene.png").is_file()


def test_an_arm_forced_off_its_command_is_said_to_be() -> None:
    """Pressed 0.3 rad off its command: the sentence says so; 0.02 rad is tracking."""
    pressed = _trace((0.5, 0.0, 0.15), force=120.0)
    pressed.q_cmd = np.where(pressed.t[:, None] > 3.0, 0.3, 0.0)
    metrics = run_metrics(pressed)
    assert metrics["max_joint_tracking_error"] == pytest.approx(0.3)
    assert ", forced up to 0.30 rad off its command (an obstacle pressed the arm" in (
        run_sentence("m", pressed, metrics)
    )
    tracked = _trace((0.5, 0.0, 0.15), force=120.0)
    tracked.q_cmd = np.full_like(tracked.q, 0.02)
    assert "forced" not in _sentence(tracked)
    assert run_metrics(_trace((0.5, 0.4, 0.15)))["max_joint_tracking_error"] is None
