"""What the teleoperation pages say: the reason the arm holds, the legend, the sliders.

The hold reason and the readout are pure functions of a session's snapshot,
tested here directly; the slider labels come from the plugins' own
descriptions of their inputs. The browser tests open the pages in headless
Chromium (slow).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from cbp.collision.contacts import ContactSet
from cbp.plugin import DescribesInput
from cbp.scenario import load_scenario
from cbp.teleop import Snapshot
from cbp.teleop.hold import DEADLINE_HOLDS, HOLDS, HoldFacts, hold_reason
from cbp.teleop.inputs_page import slider_specs
from cbp.teleop.readout import LEGEND, legend_html, readout_lines
from tests.conftest import free_port, headless_chromium

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


def _snapshot(**values: object) -> Snapshot:
    fields: dict[str, object] = {
        "t": 3.0,
        "q": np.zeros(7),
        "hand": np.zeros(3),
        "method": "cat",
        "paused": False,
        "steps": 12,
        "misses": 0,
        "contact_force": 0.0,
    }
    fields.update(values)
    return Snapshot(**fields)  # type: ignore[arg-type]


def _contacts(distances: list[float]) -> ContactSet:
    n = len(distances)
    return ContactSet(
        np.zeros(n, dtype=np.intp),
        np.full(n, -1, dtype=np.intp),
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        np.tile([0.0, 0.0, 1.0], (n, 1)),
        np.array(distances, dtype=float),
    )


def test_nothing_holds_an_arm_that_follows_its_goal() -> None:
    """No reason while the arm has not stopped short, whatever held a step."""
    facts = HoldFacts(short=False, held_by=frozenset({"contact"}), goal_space="free")
    assert hold_reason(facts) is None


def test_the_hold_reason_names_what_holds_the_arm_in_order() -> None:
    """Pause, cameras, goal space, reach, deadlines, then what held the planner."""
    short = HoldFacts(short=True)
    cases = [
        (HoldFacts(paused=True), "paused"),
        (
            HoldFacts(note="no valid frame from camera 'head' ...: robot stopped"),
            "perception",
        ),
        (
            HoldFacts(
                short=True, goal_space="obstacle", held_by=frozenset({"contact"})
            ),
            "goal in obstacle",
        ),
        (HoldFacts(short=True, goal_space="unseen"), "goal in unseen space"),
        (
            HoldFacts(short=True, clamped="1.40 m from the arm's first joint"),
            "out of reach",
        ),
        (
            HoldFacts(
                short=True,
                recent_misses=DEADLINE_HOLDS,
                held_by=frozenset({"contact"}),
            ),
            "deadline",
        ),
        (
            HoldFacts(short=True, held_by=frozenset({"contact", "joint limit"})),
            "contact",
        ),
        (HoldFacts(short=True, held_by=frozenset({"joint limit"})), "joint limit"),
        (
            HoldFacts(short=True, held_by=frozenset({"self-collision"})),
            "self-collision",
        ),
        (HoldFacts(short=True, held_by=frozenset({"keep_out"})), "held"),
        (short, "out of reach"),
        (HoldFacts(short=True, method="mp", note="no plan found"), "stopped short"),
    ]
    for facts, kind in cases:
        hold = hold_reason(facts)
        assert hold is not None, facts
        assert hold.kind == kind, (facts, hold)
        assert hold.kind in HOLDS
        assert hold.text.startswith(HOLDS[kind].split(":")[0])
    clamped = hold_reason(HoldFacts(short=True, clamped="beyond its reach (1.2 m)"))
    assert clamped is not None
    assert "beyond its reach (1.2 m)" in clamped.text
    held = hold_reason(HoldFacts(short=True, held_by=frozenset({"keep_out"})))
    assert held is not None
    assert "keep_out" in held.text


def test_the_readout_says_the_hold_and_keeps_clearance_apart_from_touch() -> None:
    """The hold leads the readout; 0 mm clearance is not mistaken for a touch."""
    snap = _snapshot(contacts=_contacts([0.0, 0.002, 0.03]), misses=7, recent_misses=2)
    hold = hold_reason(HoldFacts(short=True, goal_space="obstacle"))
    lines = readout_lines(snap, 0.12, hold, 2.5)
    text = "\n".join(lines)
    assert lines[2] == "**holds: the goal lies inside an obstacle** (since 2.50 s)"
    assert "touching an obstacle: no (contact force 0 N)" in text
    assert "0.0 mm beyond the links' padding, 2 contacts holding the arm" in text
    assert "clearance" not in text
    assert "deadline misses: 7 (2 in the last second)" in text
    touching = "\n".join(readout_lines(_snapshot(contact_force=12.5), 0.0, None, None))
    assert "touching an obstacle: **yes**, 12.5 N" in touching
    assert "at the goal" in touching
    assert "none within reach" in touching
    following = readout_lines(_snapshot(), 0.1, None, None)
    assert following[2] == "following the goal"


def test_the_legend_names_every_colour_the_page_draws() -> None:
    """A swatch and a line per entry: the gripper, the posture, the arrows."""
    html = legend_html()
    texts = [text for _, text in LEGEND]
    assert all(text in html for text in texts)
    assert html.count("background:rgb") == len(LEGEND)
    joined = " ".join(texts)
    for word in ("gripper", "closest posture", "blocked direction", "may not move"):
        assert word in joined
    assert len({colour for colour, _ in LEGEND}) == len(LEGEND)  # told apart


def test_orbit_and_pan_sliders_are_named_by_meaning_with_units() -> None:
    """Camera velocities in m/s per axis, the distance r_d in m, in ranges."""
    labels = {}
    for name in ("youbot_orbit_case1.yaml", "youbot_pan.yaml"):
        scenario = load_scenario(SCENARIOS / name)
        names = {id(e.plugin): e.name for e in scenario.entries}
        for plugin, functions in scenario.inputs():
            assert isinstance(plugin, DescribesInput)
            values = np.array([f(0.0) for f in functions])
            specs = slider_specs(names[id(plugin)], plugin, values)
            for spec, value in zip(specs, values, strict=True):
                assert spec.low <= value <= spec.high
                assert "[" not in spec.label.split(" [")[0]  # no raw index
                labels[spec.label] = (spec.low, spec.high)
    assert set(labels) == {
        "camera velocity forward, along its line of sight (x) [m/s]",
        "camera velocity sideways (y) [m/s]",
        "camera velocity up (z) [m/s]",
        "distance to the object (r_d) [m]",
    }
    assert labels["camera velocity sideways (y) [m/s]"] == (-0.3, 0.3)
    low, high = labels["distance to the object (r_d) [m]"]
    assert 0.0 < low < 0.6 < high


def test_an_input_its_plugin_does_not_describe_keeps_indexed_sliders() -> None:
    """Without a description: entry[i], from 0 to twice a positive start."""
    specs = slider_specs("gain", object(), np.array([0.5, -0.1]))
    assert [(s.label, s.low, s.high) for s in specs] == [
        ("gain[0]", 0.0, 1.0),
        ("gain[1]", -0.2, 0.2),
    ]


@pytest.mark.slow
def test_the_orbit_page_shows_sliders_by_meaning_in_the_browser() -> None:
    """Headless Chromium shows the sliders' meanings and units, not raw names."""
    pytest.importorskip("viser", reason="the viewer extra is not installed")
    from cbp.teleop import InputSession
    from cbp.teleop.inputs_page import InputsPage

    session = InputSession(
        [SCENARIOS / "youbot_orbit_case1.yaml", SCENARIOS / "youbot_pan.yaml"]
    )
    page = InputsPage(session, port=free_port())
    browser = headless_chromium()
    try:
        browser.get(page.url)

        def text() -> str:
            return str(browser.execute_script("return document.body.innerText"))

        deadline = time.monotonic() + 60
        while "distance to the object (r_d) [m]" not in text():
            assert time.monotonic() < deadline, "the sliders never came"
            time.sleep(0.1)
        source = text()
        assert "camera velocity sideways (y) [m/s]" in source
        assert "user_velocity[0]" not in source
        assert "distance[0]" not in source
    finally:
        browser.quit()
        page.close()
        session.stop()
