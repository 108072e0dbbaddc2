"""A floor under a fixed arm's base: the base touches it, and no motion can change that.

The first thing a user adds to a scene of their own. The links no joint moves
are left out of the obstacle checks (``RobotModel.fixed_links``); before, CAT
backed out of the floor forever (declared objects) or eased contact rows of
the base every period (the cameras' map) and never moved.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cbp.executors.cat import run_cat
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario
from cbp.state import RobotState

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
TABLE = (
    "{name: table, shape: box, size: [0.60, 1.20, 0.04], "
    "pose: {position: [0.55, 0.0, -0.02]}}"
)


def _floor_scene(tmp_path: Path, top: float) -> Path:
    """cat_free_step with a 2 m floor whose top is at ``top`` [m] instead of the table."""
    text = (SCENARIOS / "cat_free_step.yaml").read_text()
    assert TABLE in text
    floor = (
        "{name: floor, shape: box, size: [2.0, 2.0, 0.04], "
        f"pose: {{position: [0.0, 0.0, {top - 0.02}]}}}}"
    )
    text = text.replace(TABLE, floor).replace(
        "include: configs/cat.yaml", f"include: {SCENARIOS}/configs/cat.yaml"
    )
    path = tmp_path / "floor.yaml"
    path.write_text(text)
    return path


def test_the_fixed_links_are_the_base() -> None:
    """The Panda's link0 is fixed; a mobile base has none."""
    panda = load_scenario(SCENARIOS / "cat_free_step.yaml").robot
    assert panda.fixed_links() == {"panda_link0"}
    youbot = load_scenario(SCENARIOS / "youbot_orbit_case1.yaml").robot
    assert youbot.fixed_links() == frozenset()


def test_a_floor_through_the_base_is_no_contact(tmp_path: Path) -> None:
    """A floor 1 cm up the base loads, and no contact is found on the base."""
    scenario = load_scenario(_floor_scene(tmp_path, 0.01))
    world = scenario.world_for_run()
    world.set_environment(scenario.new_world().environment)
    contacts = world.query(RobotState(scenario.robot, scenario.q0))
    obstacles = contacts.environment_part()
    links = {world.geometry.shapes[k].link for k in obstacles.shape}
    assert "panda_link0" not in links
    assert np.all(obstacles.distance > 0.0)


@pytest.mark.parametrize("top", [0.0, 0.01])
def test_cat_reaches_over_a_floor_under_its_base(tmp_path: Path, top: float) -> None:
    """Declared objects: reached, no event, 0 N (before: held from the start).

    With the floor 1 cm up the base, the simulator's penetration does not
    count the base in it either.
    """
    scenario = load_scenario(
        _floor_scene(tmp_path, top),
        overrides={"method.cat.timing.clock": "virtual", "duration": "2.5"},
    )
    trace = run_cat(scenario)
    metrics = run_metrics(trace, scenario.robot)
    assert metrics["reached"], trace.events
    assert trace.events == []
    assert metrics["peak_contact_force_n"] == 0.0
    assert metrics["physical_penetration_m"] == 0.0


@pytest.mark.slow
def test_cat_reaches_over_a_floor_the_cameras_see(tmp_path: Path) -> None:
    """The cameras' map of the floor: reached, no eased rows of the base."""
    scenario = load_scenario(
        _floor_scene(tmp_path, 0.0),
        overrides={
            "method.cat.timing.clock": "virtual",
            "perception.source": "depth_camera",
            "duration": "2.5",
        },
    )
    trace = run_cat(scenario)
    metrics = run_metrics(trace, scenario.robot)
    assert metrics["reached"], trace.events[:5]
    assert not any("QP eased" in m for _, m in trace.events)
    assert metrics["peak_contact_force_n"] == 0.0


def test_the_simulator_counts_no_penetration_of_a_base_on_the_floor(
    tmp_path: Path,
) -> None:
    """The xArm 6 on a floor: PyBullet finds its base 1.5 mm in; not the arm's."""
    import pybullet_data

    urdf = Path(pybullet_data.getDataPath()) / "xarm" / "xarm6_robot.urdf"
    path = tmp_path / "xarm_floor.yaml"
    path.write_text(
        f"name: xarm_floor\ninclude: {SCENARIOS}/configs/cat.yaml\n"
        f"robot: {{name: {urdf}}}\nduration: 0.3\n"
        "goal: {type: keyframes, keyframes: "
        "[{t: 0.0, pose: {position: [0.3, 0.0, 0.3], rpy_deg: [180, 0, 0]}}]}\n"
        "world: {objects: [{name: floor, shape: box, size: [2.0, 2.0, 0.04], "
        "pose: {position: [0.0, 0.0, -0.02]}}]}\n"
    )
    scenario = load_scenario(path, overrides={"method.cat.timing.clock": "virtual"})
    metrics = run_metrics(run_cat(scenario), scenario.robot)
    assert metrics["physical_penetration_m"] == 0.0
    assert metrics["peak_contact_force_n"] == 0.0
