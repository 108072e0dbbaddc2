"""Generic contract checks over every registered plugin."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cbp.errors import ScenarioError
from cbp.plugin import Constraint, Task
from cbp.plugins.tasks import TASKS
from cbp.schema import from_plain, to_plain
from cbp.state import RobotState
from cbp.testing import sample_configurations
from tests.plugin_cases import PLUGIN_CASES, PluginCase

CASES = [(case, robot) for case in PLUGIN_CASES for robot in case.robots]


@pytest.mark.parametrize(
    ("case", "robot_name"), CASES, ids=[f"{c.type_name}-{r}" for c, r in CASES]
)
def test_outputs_have_the_declared_shapes_and_are_pure(
    case: PluginCase, robot_name: str, robots, rng
) -> None:
    """Value (dim,), Jacobian (dim, nv), finite; state and plugin unchanged."""
    robot = robots[robot_name]
    plugin = case.build(robot)
    assert plugin.type_name in repr(plugin)
    for q in sample_configurations(robot, rng, n=2):
        state = RobotState(robot, q)
        plugin.prepare(state, 0.01)
        before = repr(plugin)
        value, J = plugin.linearize(state)
        assert value.shape == (plugin.dim,)
        assert J.shape == (plugin.dim, robot.nv)
        assert value.dtype == np.float64
        assert J.dtype == np.float64
        assert np.all(np.isfinite(value))
        assert np.all(np.isfinite(J))
        np.testing.assert_array_equal(state.q, q)
        assert repr(plugin) == before
        if isinstance(plugin, Constraint):
            lower, upper = plugin.compute_bounds(state)
            assert lower.shape == upper.shape == (plugin.dim,)
            assert np.all(lower <= upper)


@pytest.mark.parametrize("case", PLUGIN_CASES, ids=lambda c: c.type_name)
def test_params_round_trip_and_reject_unknown_keys(case: PluginCase, robots) -> None:
    """Dict -> Params -> dict is the identity; an unknown key is named."""
    robot = robots[case.robots[0]]
    params_cls = type(case.build(robot).params)
    params = case.build(robot).params
    plain = to_plain(params)
    assert to_plain(from_plain(params_cls, plain)) == plain
    with pytest.raises(ScenarioError, match="unknown key 'bogus'"):
        from_plain(params_cls, {**plain, "bogus": 1.0})
    for f in dataclasses.fields(params_cls):
        if (
            f.default is dataclasses.MISSING
            and f.default_factory is dataclasses.MISSING
        ):
            reduced = {k: v for k, v in plain.items() if k != f.name}
            with pytest.raises(ScenarioError, match=f"missing required key '{f.name}'"):
                from_plain(params_cls, reduced)


#: The task cases (every registered task), on each of their robots.
TASK_CASES = [(c, r) for c, r in CASES if c.type_name in TASKS.names()]


@pytest.mark.parametrize(
    ("case", "robot_name"),
    TASK_CASES,
    ids=[f"{c.type_name}-{r}" for c, r in TASK_CASES],
)
def test_a_step_limited_in_place_is_the_step_limit_step_returns(
    case: PluginCase, robot_name: str, robots, rng
) -> None:
    """A task's limit_step_into writes what limit_step returns, bit for bit."""
    robot = robots[robot_name]
    plugin = case.build(robot)
    assert isinstance(plugin, Task)
    for q in sample_configurations(robot, rng, n=2):
        state = RobotState(robot, q)
        plugin.prepare(state, 0.01)
        value = plugin.compute_value(state)
        for scale in (1e-3, 1.0, 100.0):  # within the limits, and beyond them
            desired = -scale * value
            kept = desired.copy()
            limited = np.array(plugin.limit_step(desired))
            np.testing.assert_array_equal(desired, kept)  # limit_step copies
            plugin.limit_step_into(desired)
            np.testing.assert_array_equal(desired, limited)
