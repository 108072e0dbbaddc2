# SPDX-License-Identifier: Apache-2.0
"""The engine's compiled kernels are compiled when it is built, not in its steps."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_steps_compile_nothing_after_the_engine_is_built() -> None:
    """Orbit ticks and reaching steps add no signature to the kernels they run.

    In a fresh process: a kernel warmed on other array kinds (read-only or
    writeable, C or Fortran order) than a step passes would be compiled
    again, or loaded from numba's cache, in the control loop's first tick.
    """
    script = """
import numpy as np
from benchmarks.bench import GOALS, _engine
from cbp.engine import ahead, engine as engine_module, guard
from cbp.plugins.constraints import joint_acceleration_constraint as acceleration
from cbp.plugins.constraints import view_direction_constraint as view
from cbp.plugins.tasks import goal_pose_task as goal_pose
from cbp.robot import RobotModel
from cbp.scenario import load_scenario

kernels = {
    "view_rows": view._view_rows,
    "apply_coasting": ahead._apply_coasting,
    "holding": ahead._holding,
    "refine_rows": ahead._refine_rows,
    "step_bounds": acceleration._step_bounds,
    "limit_step": goal_pose._limit_step,
    "all_finite": engine_module._all_finite,
    "euclidean_check": guard._euclidean_check,
    "speed_ratio": guard._speed_ratio,
    "acceleration_ratio": guard._acceleration_ratio,
    "past_limits": guard._past_limits,
}
orbit = load_scenario("scenarios/youbot_orbit_case1.yaml")
engine, inputs, robot = orbit.make_engine(), orbit.inputs(), orbit.robot
panda = RobotModel.load("franka_panda")
reaching, goal = _engine(panda, "daqp")
built = {name: len(k.signatures) for name, k in kernels.items()}
q, v, dt = orbit.q0.copy(), np.zeros(robot.nv), 0.02
for i in range(60):
    for plugin, functions in inputs:
        plugin.set_input(np.array([f(dt * i) for f in functions]))
    dq = engine.step(q, dt, v).dq
    q, v = robot.integrate(q, dq), dq / dt
assert np.any(v != 0.0)
p = panda.home()
for i in range(5):
    goal.set_target(GOALS[i % 3].translation, GOALS[i % 3].rotation)
    p = panda.integrate(p, reaching.step(p, 0.01).dq)
stepped = {name: len(k.signatures) for name, k in kernels.items()}
assert built == stepped == dict.fromkeys(kernels, 1), (built, stepped)
"""
    run = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert run.returncode == 0, run.stderr[-2000:]
