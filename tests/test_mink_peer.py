"""The mink peer of ``cbp bench``: the engine's Panda on MuJoCo, and a reach."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from benchmarks.bench import DT, GOALS
from benchmarks.mink_peer import MinkReach, mujoco_model
from cbp.errors import ConfigError
from cbp.metrics import REACH_POSITION, REACH_ROTATION
from cbp.robot import RobotModel

mujoco = pytest.importorskip("mujoco", reason="mujoco is a bench extra")
pytest.importorskip("mink", reason="mink is a bench extra")


@pytest.fixture(scope="module")
def panda() -> RobotModel:
    return RobotModel.load("franka_panda")


def test_mujoco_model_places_every_body_as_pinocchio_does(panda: RobotModel) -> None:
    """Same joints; hand and fingers (locked at 4 cm) where pinocchio puts them."""
    model = mujoco_model(panda)
    assert model.nq == model.nv == panda.nq == 7
    assert model.neq == 0  # the fingers' mimic constraint went with them
    data = mujoco.MjData(model)
    pin_data = panda.model.createData()
    rng = np.random.default_rng(0)
    for q in (panda.home(), *(panda.random_configuration(rng) for _ in range(5))):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        pin.framesForwardKinematics(panda.model, pin_data, q)
        for link in ("panda_link3", "panda_hand", "panda_leftfinger"):
            body, frame = model.body(link).id, panda.frame_id(link)
            placement = pin_data.oMf[frame]
            np.testing.assert_allclose(
                data.xpos[body], placement.translation, atol=1e-9
            )
            rotation = data.xmat[body].reshape(3, 3)
            np.testing.assert_allclose(rotation, placement.rotation, atol=1e-9)


def test_mink_step_reaches_each_goal_within_cbp_tolerances(panda: RobotModel) -> None:
    """From home, each benchmark goal in turn, inside the joint limits."""
    peer = MinkReach(panda, panda.home(), GOALS, DT)
    for goal in range(len(GOALS)):
        before = peer.error(goal)
        steps = peer.reach(goal, 200)
        assert steps is not None, f"goal {goal} not reached: {peer.error(goal)}"
        distance, angle = peer.error(goal)
        assert distance <= REACH_POSITION < before[0]
        assert angle <= REACH_ROTATION
        q = peer.configuration.q
        assert np.all(q >= panda.lower_limits)
        assert np.all(q <= panda.upper_limits)


def test_mink_steps_keep_the_velocity_limits(panda: RobotModel) -> None:
    """The benchmark's calls: within the URDF's velocity limits, closing in."""
    peer = MinkReach(panda, panda.home(), GOALS, DT)
    step = peer.stepper(64)
    speeds, distances = [], [peer.error(0)[0]]
    for i in range(64):
        speeds.append(np.abs(step(i)))
        distances.append(peer.error(0)[0])
    assert np.all(np.array(speeds) <= panda.velocity_limits + 1e-9)
    assert np.any(np.array(speeds) >= 0.99 * panda.velocity_limits)  # it binds
    # Closer at every step until within the tolerance (then it settles).
    arrived = int(np.argmax(np.array(distances) <= REACH_POSITION))
    assert arrived > 0
    assert np.all(np.diff(distances[: arrived + 1]) < 0)
    assert max(distances[arrived:]) <= REACH_POSITION


def test_a_moving_base_is_refused_by_name(panda: RobotModel) -> None:
    robot = RobotModel.from_urdf(panda.urdf_path, base="planar", name="panda")
    with pytest.raises(ConfigError, match="robot 'panda': has a planar base"):
        mujoco_model(robot)
