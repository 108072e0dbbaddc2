"""The simulation's cameras: each engine's, the same frames."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cbp.perception.spec import DepthNoise
from cbp.scenario import load_scenario
from cbp.sim.camera import DepthCamera
from cbp.sim.cameras import depth_cameras
from cbp.sim.simulation import Simulation
from cbp.state import RobotState

pytest.importorskip("cbp.sim.mujoco.camera")  # MUJOCO_GL set before mujoco loads

SCENARIOS = Path(__file__).parents[2] / "scenarios"


def test_each_simulation_gives_cameras_of_its_engine_and_the_same_frames() -> None:
    """The boards' cameras on PyBullet and on MuJoCo see the same depths."""
    from cbp.sim.mujoco.camera import MujocoDepthCamera

    scenario = load_scenario(SCENARIOS / "cat_boards.yaml")
    robot = scenario.robot
    specs = [
        replace(c, noise=DepthNoise(enabled=False), width=96, height=72)
        for c in scenario.spec.perception.all_cameras
    ]
    state = RobotState(robot)
    state.update(scenario.q0)
    ranges = {}
    for simulator, kind in (("pybullet", DepthCamera), ("mujoco", MujocoDepthCamera)):
        sim = Simulation(
            robot, list(scenario.spec.world.objects), scenario.q0,
            scenario.spec.simulation, SCENARIOS, simulator=simulator,
        )  # fmt: skip
        cameras = depth_cameras(sim, specs, robot)
        assert all(type(c) is kind for c in cameras)
        assert [c.name for c in cameras] == [s.name for s in specs]
        ranges[simulator] = [
            c.capture(state if c.mounted else None).ranges() for c in cameras
        ]
        for camera in cameras:
            camera.close()
        sim.physics.close()
    for a, b in zip(ranges["pybullet"], ranges["mujoco"], strict=True):
        assert np.isfinite(a).mean() > 0.1  # the camera sees the scene
        with np.errstate(invalid="ignore"):
            same = (np.isinf(a) & np.isinf(b)) | (np.isnan(a) & np.isnan(b))
            same |= np.abs(a - b) <= 0.01
        assert same.mean() > 0.99
