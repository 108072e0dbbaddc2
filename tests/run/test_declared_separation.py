"""Speed and separation with declared moving objects."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from cbp.collision.objects import PrimitiveEnvironment
from cbp.run.events import RunLog
from cbp.run.separation import DeclaredSeparationMonitor
from cbp.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"

#: How long the arm takes to begin answering: two 30 Hz command periods [s].
REACTION = 2.0 / 30.0


@pytest.fixture
def pushed():
    """The pushed-box scene as the box starts, 3.3 cm from the padded arm at rest."""
    scenario = load_scenario(SCENARIOS / "cat_pushed_obstacle.yaml")
    world = scenario.world_for_run()
    return scenario, world, scenario.environment_objects(0.5)


def _monitor(world, objects, speed: float) -> tuple[DeclaredSeparationMonitor, RunLog]:
    """The box coming at ``speed`` [m/s] along its declared direction."""
    box = objects[1]
    direction = box.velocity / np.linalg.norm(box.velocity)
    fast = dataclasses.replace(box, velocity=speed * direction)
    world.set_environment(PrimitiveEnvironment([objects[0], fast], 0.3))
    log = RunLog("cat")
    return DeclaredSeparationMonitor(world, log), log


def test_a_box_the_arm_can_outrun_is_not_said(pushed) -> None:
    """At its declared 5 cm/s, the box is further than the arm needs."""
    scenario, world, objects = pushed
    monitor, log = _monitor(world, objects, 0.05)
    monitor.check(2.5, scenario.q0, REACTION)
    assert not monitor.short
    assert log.events == []


def test_a_box_faster_than_the_arm_can_get_away_is_said_once(pushed) -> None:
    """At 1 m/s the same box is nearer than the arm can keep from: one event."""
    scenario, world, objects = pushed
    monitor, log = _monitor(world, objects, 1.0)
    monitor.check(2.5, scenario.q0, REACTION)
    monitor.check(2.51, scenario.q0, REACTION)
    assert monitor.short
    assert monitor.times_short == 1
    [(t, message)] = log.events
    assert t == 2.5
    assert re.match(r"object 'box' comes at 9\d cm/s and is 3\.\d cm from", message)
    assert "contact is possible" in message
    # The box gone (it stopped): clear again, said once.
    world.set_environment(PrimitiveEnvironment([objects[0]], 0.3))
    monitor.check(2.6, scenario.q0, REACTION)
    assert not monitor.short
    assert log.events[-1] == (2.6, "moving obstacles are clear of the arm again")
