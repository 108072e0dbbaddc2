"""A start inside an obstacle: refused, or backed out of when allowed.

Issue 16's recovery checks, run in PyBullet: a box 5 mm and 2 cm into the
arm's lowest point (``robot.allow_initial_contact``), left by every method.
"""

from __future__ import annotations

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
from cbp.errors import ScenarioError
from cbp.executors.cat import run_cat
from cbp.scenario import load_scenario
from cbp.scenario.scene import ObjectSpec
from cbp.state import RobotState
from tests.executors.obstacles import unpadded_distance

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@pytest.mark.slow
def test_a_start_inside_a_box_backs_out_and_never_goes_deeper(tmp_path) -> None:
    """5 mm into a box with allow_initial_contact: out within 0.5 s."""
    box, head = _box_in_the_arm(0.005)
    refused = tmp_path / "inside.yaml"
    refused.write_text(head)
    with pytest.raises(ScenarioError, match="mm deep into 'box'"):
        load_scenario(refused)
    allowed = tmp_path / "allowed.yaml"
    allowed.write_text(
        head.replace("  initial:", "  allow_initial_contact: true\n  initial:", 1)
    )
    scenario = load_scenario(allowed)
    start = unpadded_distance(scenario, box, 0.0, scenario.q0)
    assert start == pytest.approx(-0.005, abs=1e-3)
    trace = run_cat(scenario)
    depth = np.array([unpadded_distance(scenario, box, 0.0, q) for q in trace.q[::10]])
    times = trace.t[::10]
    assert depth.min() >= start - 1e-3  # never deeper
    assert np.all(depth[times >= 0.5] >= 0.0), depth[times >= 0.5].min()


def _box_in_the_arm(depth: float) -> tuple[ObjectSpec, str]:
    """The pushed-box scene with a still box ``depth`` [m] into the arm's lowest point.

    Returns the box and the scenario's text (2 s; the start is refused unless
    ``robot.allow_initial_contact`` is added).
    """
    base = load_scenario(SCENARIOS / "cat_pushed_obstacle.yaml")
    state = RobotState(base.robot, base.q0)
    # The box's top ``depth`` into the arm (a bisection on coal's signed distance).
    box = ObjectSpec(
        name="box",
        shape="box",
        size=(0.2, 0.2, 0.1),
        pose=_pose_under_hand(base, state, depth=depth),
    )
    text = (
        (SCENARIOS / "cat_pushed_obstacle.yaml")
        .read_text()
        .replace("include: configs/cat.yaml", f"include: {SCENARIOS}/configs/cat.yaml")
    )
    head, _, _ = text.partition("    - name: box")
    x, y, z = box.pose.position
    head += (
        f"    - {{name: box, shape: box, size: [0.2, 0.2, 0.1], "
        f"pose: {{position: [{x}, {y}, {z}]}}}}\n"
    )
    return box, head.replace("duration: 6.0", "duration: 2.0")


def _pose_under_hand(scenario, state: RobotState, depth: float):
    """A pose for a 10 cm high box whose top is ``depth`` into the arm."""
    from cbp.spatial import Pose

    geometry = RobotGeometry(scenario.robot, padding=0.0)
    world = CollisionWorld(
        geometry,
        PrimitiveEnvironment([]),
        CollisionSettings(activation_distance=1.0, self_collision=False, padding=0.0),
    )
    hand = state.data.oMf[scenario.robot.frame_id("panda_hand")].translation

    def gap(top: float) -> float:
        slab = EnvironmentObject.primitive(
            "box",
            "box",
            (0.2, 0.2, 0.1),
            pin.SE3(np.eye(3), np.array([hand[0], hand[1], top - 0.05])),
        )
        world.set_environment(PrimitiveEnvironment([slab]))
        contacts = world.check(state.q).contacts
        return float(contacts.distance.min()) if len(contacts) else 1.0

    low, high = hand[2] - 0.5, hand[2]  # gap(low) > 0 > gap(high)
    for _ in range(50):
        mid = 0.5 * (low + high)
        if gap(mid) > -depth:
            low = mid
        else:
            high = mid
    top = 0.5 * (low + high)
    return Pose(position=(float(hand[0]), float(hand[1]), float(top - 0.05)))


@pytest.mark.slow
@pytest.mark.parametrize("method", ["cat", "ik", "mp", "hybrid"])
def test_every_method_backs_out_of_an_allowed_start_in_contact(
    tmp_path, method: str
) -> None:
    """2 cm into a box with allow_initial_contact: out within 1.5 s, said in events."""
    box, head = _box_in_the_arm(0.02)
    head = head.replace("  initial:", "  allow_initial_contact: true\n  initial:", 1)
    allowed = tmp_path / "allowed.yaml"
    allowed.write_text(head)
    virtual = {f"method.{m}.timing.clock": "virtual" for m in ("cat", "ik", "mp")}
    scenario = load_scenario(allowed, overrides={"method.name": method, **virtual})
    assert unpadded_distance(scenario, box, 0.0, scenario.q0) < -0.015
    from cbp.executors import load_executor

    trace = load_executor(method)(scenario, False)
    late = trace.t >= 1.5
    depth = np.array([unpadded_distance(scenario, box, 0.0, q) for q in trace.q[late]])
    assert depth.min() >= 0.0, depth.min()
    messages = [m for _, m in trace.events]
    assert any(m.startswith("in contact with an obstacle") for m in messages)
    assert any(m.startswith("out of contact after") for m in messages)


def test_a_start_too_deep_to_back_out_of_is_refused_at_load(tmp_path) -> None:
    """Allowed contact deeper than backing out can leave: exit at load, how deep, where."""
    from cbp.scenario.checks import ALLOWED_INITIAL_DEPTH

    _, head = _box_in_the_arm(ALLOWED_INITIAL_DEPTH + 0.01)
    deep = tmp_path / "deep.yaml"
    deep.write_text(
        head.replace("  initial:", "  allow_initial_contact: true\n  initial:", 1)
    )
    with pytest.raises(ScenarioError) as refused:
        load_scenario(deep)
    message = str(refused.value)
    assert "robot.initial" in message
    assert "mm deep into 'box', deeper than the 40 mm an arm backs out of" in message
    assert "panda_" in message  # the link
    _, head = _box_in_the_arm(0.02)  # shallower: allowed
    shallow = tmp_path / "shallow.yaml"
    shallow.write_text(
        head.replace("  initial:", "  allow_initial_contact: true\n  initial:", 1)
    )
    load_scenario(shallow)
