"""Declared objects that move are measured where they will be (``look_ahead``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from cbp.collision import (
    CollisionSettings,
    CollisionWorld,
    EnvironmentObject,
    PrimitiveEnvironment,
    RobotGeometry,
)
from cbp.run.declared import object_key
from cbp.scenario import load_scenario
from cbp.state import RobotState

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
PUSHED = SCENARIOS / "cat_pushed_obstacle.yaml"


@pytest.fixture(scope="module")
def arm():
    """The pushed-box scene's arm, its unpadded world and the hand's position."""
    scenario = load_scenario(PUSHED)
    world = CollisionWorld(
        RobotGeometry(scenario.robot, padding=0.0),
        PrimitiveEnvironment([]),
        CollisionSettings(activation_distance=0.1, self_collision=False, padding=0.0),
    )
    state = RobotState(scenario.robot, scenario.q0)
    hand = state.data.oMf[scenario.robot.frame_id("panda_hand")].translation.copy()
    return world, scenario.q0, hand


def _box_beside(hand: np.ndarray, gap: float, velocity: tuple[float, ...]):
    """A 10 cm cube ``gap`` [m] beside the hand's frame along +y, moving."""
    placement = pin.SE3(np.eye(3), hand + np.array([0.0, 0.05 + gap, 0.0]))
    box = EnvironmentObject.primitive("box", "box", (0.1, 0.1, 0.1), placement)
    return dataclasses.replace(box, velocity=np.asarray(velocity, dtype=float))


def _contacts(world: CollisionWorld, q: np.ndarray, environment):
    world.set_environment(environment)
    return world.check(q).contacts


def test_an_approaching_object_is_measured_where_it_will_be(arm) -> None:
    world, q, hand = arm
    still = _contacts(
        world, q, PrimitiveEnvironment([_box_beside(hand, 0.15, (0.0, 0.0, 0.0))])
    )
    step = np.array([0.0, -0.2, 0.0]) * 0.25  # 0.2 m/s toward the arm, 0.25 s
    coming = _box_beside(hand, 0.15, (0.0, -0.2, 0.0))
    ahead = _contacts(world, q, PrimitiveEnvironment([coming], look_ahead=0.25))
    # Each contact nearer by the box's approach along its normal (one contact
    # per shape and object; more shapes come within reach).
    assert set(still.shape) < set(ahead.shape)
    same = np.searchsorted(ahead.shape, still.shape)
    np.testing.assert_allclose(ahead.normal[same], still.normal)
    approach = np.maximum(still.normal.dot(step), 0.0)
    assert approach.max() > 0.02
    np.testing.assert_allclose(ahead.distance[same], still.distance - approach)
    # Without a look-ahead the velocity changes nothing.
    now = _contacts(world, q, PrimitiveEnvironment([coming]))
    np.testing.assert_allclose(now.distance, still.distance)


def test_an_object_out_of_reach_now_but_not_then_gives_contacts(arm) -> None:
    """The broad phase sweeps a moving object's box over the look-ahead."""
    world, q, hand = arm
    # Beyond the 10 cm activation distance now, 12.5 cm nearer then.
    coming = _box_beside(hand, 0.3, (0.0, -0.5, 0.0))
    assert not len(_contacts(world, q, PrimitiveEnvironment([coming])))
    ahead = _contacts(world, q, PrimitiveEnvironment([coming], look_ahead=0.25))
    assert len(ahead)
    assert ahead.distance.min() < 0.1


def test_an_object_moving_away_is_measured_where_it_is(arm) -> None:
    world, q, hand = arm
    still = _contacts(
        world, q, PrimitiveEnvironment([_box_beside(hand, 0.1, (0.0, 0.0, 0.0))])
    )
    assert len(still)
    away = _box_beside(hand, 0.1, (0.0, 0.3, 0.0))
    past = _box_beside(hand, 0.1, (0.0, 0.0, 0.3))  # along its face
    measured = _contacts(world, q, PrimitiveEnvironment([away], look_ahead=0.3))
    np.testing.assert_allclose(measured.distance, still.distance, atol=1e-12)
    # Sliding past, only the part of the motion toward a contact counts.
    measured = _contacts(world, q, PrimitiveEnvironment([past], look_ahead=0.3))
    approach = np.maximum(still.normal.dot(past.velocity * 0.3), 0.0)
    assert approach.min() == 0.0
    np.testing.assert_allclose(measured.distance, still.distance - approach)


def test_a_negative_look_ahead_is_refused() -> None:
    with pytest.raises(ValueError, match="look_ahead"):
        PrimitiveEnvironment([], look_ahead=-0.1)


def test_declared_objects_carry_their_velocity_while_they_move() -> None:
    scenario = load_scenario(PUSHED)
    box = next(o for o in scenario.spec.world.objects if o.name == "box")
    velocities = {
        t: next(o for o in scenario.environment_objects(t) if o.name == "box").velocity
        for t in (0.2, 2.0, 5.0)
    }
    np.testing.assert_allclose(velocities[0.2], 0.0)
    np.testing.assert_allclose(velocities[2.0], [0.0, -0.05, 0.0])
    np.testing.assert_allclose(velocities[5.0], 0.0)
    # The run rebuilds its world when the box stops, though it stays in place.
    stop = box.motion.stop
    assert (
        box.placement_at(stop).translation == box.placement_at(stop + 1).translation
    ).all()
    assert object_key([box], stop - 1e-6) != object_key([box], stop + 1.0)
