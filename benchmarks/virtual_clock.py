"""The virtual clock's costs, measured again on this machine.

Times each kind of work :class:`cbp.run.budget.VirtualCosts` charges, on
the boards scene: a CAT step (engine step, integration and step validation,
with the hand near the boards' goal), a yes-or-no collision check, one
iteration of the IK search, and timing one point of a trajectory. Prints each
with its default and their ratio: a ratio far from 1 means virtual-time runs on
this machine plan more (or less) than the same wall-clock budget would.

Run: .venv/bin/python benchmarks/virtual_clock.py
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from cbp.executors.ik_search import IkSearch
from cbp.executors.stepping import ValidatedStepper
from cbp.methods.settings import IkSettings, VirtualCosts
from cbp.run.budget import WallBudget
from cbp.scenario import load_scenario
from cbp.sim.trajectory import time_parameterize

BOARDS = Path(__file__).parents[1] / "scenarios" / "cat_boards.yaml"
REPEAT = 300
POINTS = 30


def _per_call(fn, n: int = REPEAT) -> float:  # type: ignore[no-untyped-def]
    start = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - start) / n


def main() -> None:
    scenario = load_scenario(BOARDS)
    world = scenario.world_for_run()
    engine = scenario.make_engine()
    goal_task = scenario.goal_task()
    stream = scenario.goal_stream()
    assert goal_task is not None
    assert stream is not None
    goal = stream.pose(3.0)
    goal_task.set_target(goal.translation, goal.rotation)
    stepper = ValidatedStepper(engine, world, lambda t, message: None, lambda: 0.0)
    q = scenario.q0.copy()
    stepper.start(q)
    for _ in range(50):  # into the boards, where the steps have contacts
        q = stepper.step(q, 0.01).q
    state = {"q": q}

    def cat_step() -> None:
        state["q"] = stepper.step(state["q"], 0.01).q

    search = IkSearch(scenario.robot, scenario.ee_frame, world, IkSettings().search)
    search.solves = 0
    ik_start = time.perf_counter()
    for _ in range(20):
        search.solve(goal, scenario.q0, WallBudget(10.0))
    ik = (time.perf_counter() - ik_start) / max(search.solves, 1)
    path = np.linspace(scenario.q0, q, POINTS)
    zero = np.zeros(scenario.robot.nv)
    vmax = scenario.robot.velocity_limits * 0.5
    amax = scenario.robot.acceleration_limits * 0.5
    measured = {
        "qp_step": _per_call(cat_step),
        "collision_check": _per_call(lambda: world.is_free(q)),
        "ik_iteration": ik,
        "trajectory_point": _per_call(
            lambda: time_parameterize(path, 0.0, zero, zero, vmax, amax), 50
        )
        / POINTS,
    }
    defaults = VirtualCosts()
    print("| work | measured [us] | default [us] | measured / default |")
    print("|---|---:|---:|---:|")
    for name, seconds in measured.items():
        default = getattr(defaults, name)
        print(
            f"| {name} | {seconds * 1e6:.1f} | {default * 1e6:.1f} | "
            f"{seconds / default:.2f} |"
        )


if __name__ == "__main__":
    main()
