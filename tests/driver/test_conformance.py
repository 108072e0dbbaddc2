"""The driver conformance suite (:mod:`cbp.driver.conformance`) on the simulated robots.

The same checks on the robot stepped in lockstep by the controller and on the
robot running on its own in a process (slow: a process per check).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from cbp.driver import COMMAND_TIMEOUT
from cbp.driver.conformance import CHECKS, Bench, KnownBox
from cbp.driver.process import ProcessRobot, RobotSetup
from cbp.driver.simulated import SimulatedRobot
from cbp.scenario import Scenario, load_scenario
from cbp.sim.scene import simulate
from cbp.sim.simulation import Simulation

#: A Panda, a 10 cm box in front of it, and a camera looking at the box.
SCENE = """\
name: conformance
include: configs/cat.yaml
robot: {name: franka_panda}
duration: 5.0
goal:
  type: step
  keyframes:
    - {t: 0.0, pose: {position: [0.307, 0.0, 0.590], rpy_deg: [180.0, 0.0, 0.0]}}
world:
  objects:
    - {name: box, shape: box, size: [0.1, 0.1, 0.1], pose: {position: [0.6, 0.0, 0.3]}}
perception:
  cameras:
    - {name: front, position: [1.3, 0.0, 0.3], target: [0.0, 0.0, 0.3], rate_hz: 15.0}
"""
BOX = KnownBox("front", np.array([0.55, -0.05, 0.25]), np.array([0.65, 0.05, 0.35]))


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Scenario:
    """The conformance scene, loaded from the repository's scenario folder."""
    path = Path(__file__).parents[2] / "scenarios" / "cat_free_step.yaml"
    folder = tmp_path_factory.mktemp("scene")
    (folder / "configs").symlink_to(path.parent / "configs")
    (folder / "scene.yaml").write_text(SCENE)
    return load_scenario(folder / "scene.yaml")


def _lockstep(scene: Scenario, simulator: str = "pybullet") -> Iterator[Bench]:
    spec = scene.spec
    sim = Simulation(
        scene.robot, spec.world.objects, scene.q0, spec.simulation,
        scene.path.parent, simulator=simulator,
    )  # fmt: skip
    robot = SimulatedRobot(sim, scene.spec.perception.all_cameras, COMMAND_TIMEOUT)
    try:
        yield Bench(robot, lambda s: robot.advance(robot.now() + s), BOX)
    finally:
        robot.close()


def _process(scene: Scenario, simulator: str = "pybullet") -> Iterator[Bench]:
    spec = scene.spec
    robot = ProcessRobot(
        RobotSetup(
            scene.robot,
            spec.world.objects,
            scene.q0,
            spec.simulation,
            scene.path.parent,
            tuple(spec.perception.all_cameras),
            simulator=simulator,
        )
    )
    robot.start()
    try:
        yield Bench(robot, time.sleep, BOX)
    finally:
        robot.close()


@pytest.mark.parametrize("simulator", ["pybullet", "mujoco"])
@pytest.mark.parametrize("check", CHECKS)
def test_the_robot_in_lockstep_passes(
    scene: Scenario, check: str, simulator: str
) -> None:
    """The simulated robot the controller steps (the virtual clock), either engine."""
    for bench in _lockstep(scene, simulator):
        CHECKS[check](bench)


@pytest.mark.slow
@pytest.mark.parametrize("simulator", ["pybullet", "mujoco"])
def test_the_robot_in_its_own_process_passes(scene: Scenario, simulator: str) -> None:
    """The simulated robot that runs on its own, in real time, either engine.

    One robot's process for every check (each starts a second or more), stop
    last: a stopped robot takes no more commands.
    """
    order = [name for name in CHECKS if name != "stop"] + ["stop"]
    for bench in _process(scene, simulator):
        for name in order:
            try:
                CHECKS[name](bench)
            except AssertionError as exc:
                raise AssertionError(f"check {name}: {exc}") from exc


def test_a_robot_without_a_watchdog_fails_the_stale_brake_check(
    scene: Scenario,
) -> None:
    """The check can fail: the same robot with its watchdog off keeps going."""
    sim = simulate(Simulation, scene)
    robot = SimulatedRobot(sim, (), timeout=None)
    try:
        bench = Bench(robot, lambda s: robot.advance(robot.now() + s))
        with pytest.raises(AssertionError, match="no stale-command fault"):
            CHECKS["stale_brake"](bench)
    finally:
        robot.close()


def test_the_robots_process_builds_the_engine_its_setup_names(
    scene: Scenario,
) -> None:
    """The simulator reaches the robot's process: an unknown one is refused there."""
    spec = scene.spec
    setup = RobotSetup(
        scene.robot, spec.world.objects, scene.q0, spec.simulation,
        scene.path.parent, simulator="abacus",
    )  # fmt: skip
    with pytest.raises(RuntimeError, match=r"did not start: .*unknown: 'abacus'"):
        ProcessRobot(setup)
