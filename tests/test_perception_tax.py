"""The perception-tax benchmark reads why a camera run stopped, and tabulates the tax."""

from __future__ import annotations

from benchmarks.perception_tax import reason, table

HELD = (
    "held by space no camera has seen (beside panda_hand; nearest at 0.1, 0.2, "
    "0.3 m): a camera that sees it, or perception.unknown: free, lets the arm on"
)
GOAL = (
    "goal lies in an obstacle or in space no camera has seen (perception.unknown: "
    "occupied counts it as an obstacle): the arm stops short of it"
)


def test_reasons_come_from_the_runs_events() -> None:
    """Each kind of event names its reason; a goal seen again is not one."""
    assert reason([HELD], []) == "unseen space"
    assert reason([GOAL], []) == "goal unseen"
    assert reason([GOAL, "goal is in open space again"], []) == ""
    moving = "an obstacle the cameras see moving is 3.0 cm from panda_hand, ..."
    assert reason([moving], []) == "moving obstacle"
    assert reason(["camera 'head': frame dropped, all NaN"], []) == "bad frames"
    assert reason([], ["no plan in time"]) == "no plan"
    ik = "mp: no collision-free IK solution for the goal; space no camera has seen"
    assert reason([ik], []) == "unseen space"


def _run(scene: str, source: str, reached: bool, why: str = "") -> dict[str, object]:
    return {
        "scene": scene,
        "method": "cat",
        "source": source,
        "noise": True,
        "reached": reached,
        "final_mm": 1.0 if reached else 80.0,
        "peak_n": 0.0,
        "time_s": 2.0 if reached else None,
        "reason": why,
    }


def test_the_tax_is_the_camera_reach_rate_over_the_declared_one() -> None:
    """Two declared runs reach, one camera run does: 0.50, with its reason."""
    text = table(
        [
            _run("a", "declared", True),
            _run("a", "cameras", True),
            _run("b", "declared", True),
            _run("b", "cameras", False, "unseen space"),
            {**_run("b", "cameras", True), "noise": False},
        ]
    )
    assert (
        "| b | cat | yes; 2.0 s; 0 N | no; 80 mm; 0 N | cameras: unseen space; " in text
    )
    assert "reaches at 0.1 mm" in text
    assert "reached 1 of 2 with cameras / 2 of 2 with declared objects = 0.50" in text
