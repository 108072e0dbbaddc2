# SPDX-License-Identifier: Apache-2.0
"""Run several methods on one scenario and one recorded goal stream (CAT Sec. VI).

As in the paper, the operator's goal is recorded once (``goal.csv`` in the
output folder, sampled at the command rate) and replayed to every method; each
method runs in the simulator from the same initial state. The outputs are those
of :func:`cbp.report.write_outputs`: one ``metrics.json`` with an object per method,
a table in ``report.md``, and the figures with all methods together.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cbp.executors import load_executor
from cbp.files import claim_output_folder
from cbp.goals import write_recorded
from cbp.methods import COMPARABLE, method_info
from cbp.progress import Progress
from cbp.scenario import Scenario, load_scenario
from cbp.trace import Trace

__all__ = ["ComparisonResult", "compare", "record_goal"]


@dataclass
class ComparisonResult:
    """What :func:`compare` produced.

    Attributes:
        out: the output folder.
        traces: by method.
        metrics: by method.
    """

    out: Path
    traces: dict[str, Trace]
    metrics: dict[str, dict[str, Any]]


def record_goal(scenario: Scenario, path: Path) -> bool:
    """Write the scenario's goal stream, sampled at its rate, as a recording.

    Returns:
        False if the scenario has no goal (nothing written).
    """
    stream = scenario.goal_stream()
    if stream is None:
        return False
    rate = stream.spec.rate_hz
    times = np.arange(0.0, scenario.spec.duration + 0.5 / rate, 1.0 / rate)
    samples = [stream.sample(float(t)) for t in times]
    write_recorded(
        path,
        times.tolist(),
        np.array([p for p, _ in samples]),
        np.array([R for _, R in samples]),
    )
    return True


def _run_one(path: Path, overrides: Mapping[str, str], method: str) -> Trace:
    run = load_executor(method, COMPARABLE)
    return run(load_scenario(path, overrides=overrides), False)


def compare(
    path: str | Path,
    methods: Sequence[str],
    out: Path | None = None,
    *,
    jobs: int = 1,
    overrides: Mapping[str, str] | None = None,
    progress: bool = False,
) -> ComparisonResult:
    """Run ``methods`` on the scenario at ``path``; write and return the results.

    Args:
        path: the scenario file.
        methods: comparable method names (:data:`cbp.methods.COMPARABLE`).
        out: output folder (default ``out/<scenario name>``).
        jobs: methods run in this many processes at once. Timing-dependent
            methods (CAT, IK, MP plan within wall-clock budgets) are slowed by
            sharing the cores: compare with ``jobs=1`` for timing figures.
        overrides: scenario values to replace (``--set``).
        progress: show each finished method (a bar on a terminal, else a line
            on standard error).
    """
    from cbp.report import write_outputs

    for method in methods:
        method_info(method, COMPARABLE)  # an unknown name fails before any run
    path = Path(path)
    overrides = dict(overrides or {})
    scenario = load_scenario(path, overrides=overrides)
    out = out or Path("out") / scenario.spec.name
    claim = claim_output_folder(out)  # refused if a live run writes there
    try:
        with tempfile.TemporaryDirectory(prefix="cbp-compare-") as folder:
            goal = scenario.spec.goal
            recorded = Path(folder) / "goal.csv"
            extra = {}
            if goal is not None and record_goal(scenario, recorded):
                task = f", task: {goal.task}" if goal.task else ""
                overrides["goal"] = (
                    f"{{type: recorded, file: {recorded.resolve()}, "
                    f"rate_hz: {goal.rate_hz}{task}}}"
                )
                extra["goal.csv"] = recorded
            traces: dict[str, Trace] = {}
            with Progress(len(methods), "compare", lines=progress) as bar:
                if jobs <= 1:
                    for method in methods:
                        traces[method] = _run_one(path, overrides, method)
                        bar.advance(method, traces[method].aborted is not None)
                else:
                    with ProcessPoolExecutor(max_workers=jobs) as pool:
                        futures = {
                            pool.submit(_run_one, path, overrides, m): m
                            for m in methods
                        }
                        for future in as_completed(futures):
                            method = futures[future]
                            traces[method] = future.result()
                            bar.advance(method, traces[method].aborted is not None)
                traces = {m: traces[m] for m in methods}
            # Its own failures release the claim (and keep what it wrote).
            metrics = write_outputs(scenario, traces, out, extra, claim=claim)
    except BaseException:
        claim.release(remove=not claim.released)
        raise
    return ComparisonResult(out, traces, metrics)
