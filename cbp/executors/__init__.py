# SPDX-License-Identifier: Apache-2.0
"""Executors: ways of turning the engine's steps into robot motion.

``kinematic`` integrates QP steps exactly without a simulator
(:mod:`cbp.executors.kinematic`); the others run in PyBullet and return a
:class:`~cbp.trace.RunTrace`: ``cat`` (:mod:`cbp.executors.cat`), and the CAT
paper's alternatives ``ik`` (:mod:`cbp.executors.ik`), ``mp``
(:mod:`cbp.executors.mp`) and ``jt`` (:mod:`cbp.executors.jt`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cbp.scenario import Scenario
    from cbp.trace import RunTrace

__all__ = ["SIMULATED_METHODS", "run_simulated"]

#: Methods that run in the simulator, in the order reports list them.
SIMULATED_METHODS = ("cat", "ik", "mp", "jt")


def run_simulated(scenario: Scenario, method: str, gui: bool = False) -> RunTrace:
    """Run ``scenario`` with the simulated executor ``method``."""
    if method == "cat":
        from cbp.executors.cat import run_cat

        return run_cat(scenario, gui)
    if method == "ik":
        from cbp.executors.ik import run_ik

        return run_ik(scenario, gui)
    if method == "mp":
        from cbp.executors.mp import run_mp

        return run_mp(scenario, gui)
    if method == "jt":
        from cbp.executors.jt import run_jt

        return run_jt(scenario, gui)
    raise ValueError(
        f"unknown method '{method}'; simulated methods: {', '.join(SIMULATED_METHODS)}"
    )
