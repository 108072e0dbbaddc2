"""The simulated Panda: holding, following a trajectory, measuring contact."""

from __future__ import annotations

import numpy as np
import pytest

from cbp.robot import RobotModel
from cbp.scenario.scene import ObjectSpec
from cbp.sim.simulation import Simulation
from cbp.sim.trajectory import time_parameterize
from cbp.spatial import Pose


@pytest.fixture(scope="module")
def panda() -> RobotModel:
    return RobotModel.load("franka_panda")


def test_holds_its_pose_against_gravity(panda: RobotModel) -> None:
    """The impedance law with the same model's dynamics holds the home pose."""
    q0 = panda.home()
    with Simulation(panda, [], q0) as sim:
        sim.run_until(0.3)
        assert sim.steps == 300
        np.testing.assert_allclose(sim.q, q0, atol=1e-4)


def test_follows_a_spliced_trajectory(panda: RobotModel) -> None:
    """Tracking error stays small; the robot ends at rest at the last point."""
    q0 = panda.home()
    q1 = q0 + np.array([0.6, 0.3, -0.4, 0.4, 0.5, -0.3, 0.6])
    vmax, amax = 0.5 * panda.velocity_limits, 0.5 * panda.acceleration_limits
    with Simulation(panda, [], q0) as sim:
        traj = time_parameterize(
            np.linspace(q0, q1, 100), 0.1, 0 * q0, 0 * q0, vmax, amax
        )
        assert traj is not None
        sim.follow(sim.trajectory.splice(traj))
        sim.run_until(traj.end_time + 0.2)
        rec = sim.recording()
        assert np.max(np.abs(rec["q"] - rec["q_cmd"])) < 5e-3
        np.testing.assert_allclose(sim.q, q1, atol=1e-3)
        np.testing.assert_allclose(sim.v, 0.0, atol=1e-2)
        assert rec["contact_force"].max() == 0.0


def test_measures_contact_force_when_pushed_into_a_box(panda: RobotModel) -> None:
    """Commanded through a box, the hand presses on it: force on the hand, > 0."""
    q0 = panda.home()
    box = ObjectSpec(
        name="box",
        shape="box",
        size=(0.3, 0.3, 0.3),
        pose=Pose(position=(0.35, 0.0, 0.3)),
    )
    # Joint 4 unfolds: the hand goes down into the box's top face (z = 0.45).
    q1 = q0.copy()
    q1[1] += 0.5
    with Simulation(panda, [box], q0) as sim:
        vmax, amax = 0.3 * panda.velocity_limits, 0.3 * panda.acceleration_limits
        traj = time_parameterize(
            np.linspace(q0, q1, 50), 0.0, 0 * q0, 0 * q0, vmax, amax
        )
        assert traj is not None
        sim.follow(traj)
        sim.run_until(traj.end_time + 0.2)
        rec = sim.recording()
    assert rec["contact_force"].max() > 1.0
    assert rec["wrist_force"].max() > 1.0
    assert rec["penetration"].max() < 0.02
