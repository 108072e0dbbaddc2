"""Every registered plugin's Jacobian matches central finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from cbp.testing import check_jacobian, sample_configurations
from tests.plugin_cases import PLUGIN_CASES, PluginCase

CASES = [(case, robot) for case in PLUGIN_CASES for robot in case.robots]


@pytest.mark.parametrize(
    ("case", "robot_name"), CASES, ids=[f"{c.type_name}-{r}" for c, r in CASES]
)
def test_jacobian_matches_central_differences(
    case: PluginCase, robot_name: str, robots, rng: np.random.Generator
) -> None:
    """The analytic Jacobian equals the finite-difference one at random q."""
    robot = robots[robot_name]
    plugin = case.build(robot)
    accept = (lambda q: case.accept(robot, q)) if case.accept else None
    for q in sample_configurations(robot, rng, n=4, accept=accept):
        check_jacobian(plugin, robot, q, atol=case.atol)
