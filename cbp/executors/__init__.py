# SPDX-License-Identifier: Apache-2.0
"""Executors: ways of turning the engine's steps into robot motion.

What each method is (its settings, colour, what it can do) is declared once,
in the method table :data:`cbp.methods.METHODS`; this package runs them. The
module named by a method's row holds ``run_<name>(scenario, gui=False)``, which
returns a :class:`~cbp.trace.Trace`, and, for a method that plans per command
period, ``make_planner(scenario, parts)``. Modules that need PyBullet or OMPL
are imported only when their method is used.

Every executor returns a :class:`~cbp.trace.Trace`, so one writer
(:func:`cbp.report.write_outputs`) gives every method its metrics, figures and
report.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import TYPE_CHECKING

from cbp.methods import method_info

if TYPE_CHECKING:
    from cbp.run import RunParts
    from cbp.run.plan import Planner
    from cbp.scenario.runtime import Scenario
    from cbp.trace import Trace

__all__ = ["Executor", "load_executor", "make_planner", "run_periodic"]


#: Runs a scenario for its duration (``run(scenario, gui)``; ``gui`` opens the
#: simulator's window where there is one) and returns the trace.
Executor = Callable[["Scenario", bool], "Trace"]


def load_executor(name: str, choices: tuple[str, ...] | None = None) -> Executor:
    """Import method ``name``'s module and return its ``run_<name>`` function.

    Raises:
        ConfigError: ``name`` is not a method (or not among ``choices``).
    """
    row = method_info(name, choices)
    module = importlib.import_module(f"cbp.executors.{row.module}")
    executor: Executor = getattr(module, f"run_{row.name}")
    return executor


def make_planner(name: str, parts: RunParts) -> Planner:
    """Method ``name``'s per-period planner for the run made of ``parts``.

    It plans with the run's own plugins and world (``parts.scenario``, bound
    for this run by :func:`~cbp.run.build_run`).

    Raises:
        ConfigError: ``name`` is not a method.
        ValueError: the method does not plan per command period.
    """
    row = method_info(name)
    if not row.periodic:
        raise ValueError(f"the {name} executor has no per-period planner")
    module = importlib.import_module(f"cbp.executors.{row.module}")
    planner: Planner = module.make_planner(parts.scenario, parts)
    return planner


def run_periodic(scenario: Scenario, method: str, gui: bool = False) -> Trace:
    """Run ``scenario`` with periodic method ``method``; return the trace.

    The one runner of every method that plans per command period (the
    ``run_<name>`` of CAT, IK, MP and the hybrid): its parts from
    :func:`~cbp.run.build_run`, its planner from the method's module, the
    loop (:func:`~cbp.run.loop.run_loop`) timed by the scenario's
    ``method:`` section.
    """
    from cbp.run import build_run
    from cbp.run.loop import run_loop

    timing = scenario.spec.method.timing(method)
    parts = build_run(scenario, method=method, gui=gui, clock=timing.clock)
    try:
        planner = make_planner(method, parts)
    except BaseException:
        parts.close()
        raise
    return run_loop(parts, planner, timing)
