"""``cbp robot-pairs``: sampled ignore pairs, printed ready for robot.yaml."""

from __future__ import annotations

import yaml

from cbp.collision import RobotGeometry
from tests.conftest import run_cbp


def test_robot_pairs_prints_yaml_of_non_adjacent_pairs(robots) -> None:
    result = run_cbp("robot-pairs", "franka_panda", "--samples", "300")
    assert result.returncode == 0, result.stderr
    pairs = yaml.safe_load(result.stdout)["collision"]["ignore_pairs"]
    assert pairs
    geometry = RobotGeometry(robots["panda"])
    links = {s.link for s in geometry.shapes}
    for a, b in pairs:
        assert a in links
        assert b in links
    # The hand reaching the base is a real self-collision: never ignored.
    assert ["panda_hand", "panda_link0"] not in pairs
    assert ["panda_link0", "panda_hand"] not in pairs
    # The pairs robot.yaml already ignores are sampled too: the list is whole.
    description = robots["panda"].description
    assert description is not None
    for a, b in description.collision.ignore_pairs:
        assert sorted([a, b]) in [sorted(p) for p in pairs]


def test_robot_pairs_needs_samples() -> None:
    result = run_cbp("robot-pairs", "franka_panda", "--samples", "0")
    assert result.returncode == 2
    assert "must be >= 1" in result.stderr


def test_unknown_robot_is_named() -> None:
    result = run_cbp("robot-pairs", "franka_pand")
    assert result.returncode == 2
    assert "franka_panda" in result.stderr
