# SPDX-License-Identifier: Apache-2.0
"""``cbp run`` and ``cbp compare``: one method, or several on one goal stream."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cbp.cli.command import Command, add_set, read_overrides
from cbp.errors import CbpError, ConfigError
from cbp.methods import COMPARABLE, METHODS

if TYPE_CHECKING:
    from cbp.executors import Executor
    from cbp.files import OutputClaim
    from cbp.scenario import Scenario
    from cbp.trace import Trace

__all__ = ["COMPARE", "RUN"]


def _run_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", type=Path)
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default out/<name>)"
    )
    parser.add_argument(
        "--method",
        default=None,
        help=f"executor: {', '.join(METHODS)} (default: the scenario's method.name)",
    )
    parser.add_argument("--gui", action="store_true", help="show PyBullet's window")
    add_set(
        parser,
        "override a scenario value, e.g. --set perception.source=depth_camera",
    )


def _run(args: argparse.Namespace) -> int:
    from cbp.executors import load_executor
    from cbp.scenario import load_scenario

    overrides = read_overrides(args.set)
    if overrides is None:
        return 2
    try:
        scenario = load_scenario(args.scenario, overrides=overrides)
        name = args.method or scenario.spec.method.name
        executor = load_executor(name)
        METHODS[name].refuse_source(
            scenario.spec.perception.source, f"{scenario.path}: perception.source"
        )
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    out = args.out or Path("out") / scenario.spec.name
    from cbp.files import claim_output_folder

    try:
        claim = claim_output_folder(out)  # refused if a live run writes there
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    return _run_and_write(scenario, name, executor, args.gui, claim)


def _run_and_write(
    scenario: Scenario,
    name: str,
    executor: Executor,
    gui: bool,
    claim: OutputClaim,
) -> int:
    """Run, write the outputs into ``claim``'s folder; the exit status.

    SIGINT, SIGTERM and SIGHUP never lose what ran: the first stops the run,
    which brakes and writes all its outputs (exit 3, aborted); a later one, or
    one while the outputs are written, leaves the figures and the report out
    (exit 130); the trace and the metrics are always written.
    """
    from cbp.interrupts import SignalGuard
    from cbp.progress import run_progress
    from cbp.report import write_outputs
    from cbp.run.faults import STOPPED_EARLY, clear_stop, request_stop

    def stop_the_run(signal_name: str) -> None:
        if len(guard.received) == 1:
            request_stop(signal_name)

    out = claim.out
    guard = SignalGuard(stop_the_run)
    clear_stop()
    try:
        with guard:
            try:
                with run_progress(f"{scenario.spec.name} ({name})"):
                    trace = executor(scenario, gui)
            except ConfigError as exc:  # as the run starts (a URDF PyBullet refuses)
                claim.release(remove=True)
                print(exc, file=sys.stderr)
                return 2
            except BaseException:
                claim.release(remove=True)
                raise
            stopped = (trace.aborted or "").startswith(STOPPED_EARLY)
            guard.answered = min(len(guard.received), int(stopped))
            try:
                metrics = write_outputs(
                    scenario, {name: trace}, out, claim=claim, guard=guard
                )[name]
            except CbpError as exc:  # the folder changed during the run
                print(exc, file=sys.stderr)
                return 1
    finally:
        clear_stop()
    return _said(scenario, name, trace, metrics, out, guard.unanswered)


def _said(
    scenario: Scenario,
    name: str,
    trace: Trace,
    metrics: dict[str, Any],
    out: Path,
    interrupted_by: list[str],
) -> int:
    """Say how the run and its outputs went; the exit status."""
    from cbp.report import summary_line
    from cbp.run.faults import EXIT_ABORTED, EXIT_INCOMPLETE

    print(summary_line(scenario, name, metrics))
    if interrupted_by:
        print(f"wrote {out}/metrics.json and trace.csv")
        print(
            f"{interrupted_by[0]}: not written: "
            f"{', '.join(metrics.get('incomplete', []))} (see the events in "
            f"{out}/metrics.json)",
            file=sys.stderr,
        )
        return 130
    print(f"wrote {out}/report.md, metrics.json, trace.csv and plots")
    if trace.aborted:
        return EXIT_ABORTED
    if metrics.get("incomplete"):
        print(
            f"not written: {', '.join(metrics['incomplete'])} (see the events in "
            f"{out}/metrics.json)",
            file=sys.stderr,
        )
        return EXIT_INCOMPLETE
    return 0


def _compare_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", type=Path)
    parser.add_argument(
        "--methods",
        default=",".join(COMPARABLE),
        help=f"comma-separated, from {', '.join(COMPARABLE)} (default: all)",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default out/<name>)"
    )
    parser.add_argument(
        "--jobs", type=int, default=1, help="methods run in this many processes"
    )
    parser.add_argument(
        "--goal",
        type=Path,
        default=None,
        help="replay this recorded goal file (a teleop session's operator_goal.csv)"
        " instead of the scenario's goal, until its end and 2 s more",
    )
    add_set(parser, "override a scenario value (as for run)")


def _compare(args: argparse.Namespace) -> int:
    from cbp.compare import compare

    overrides = read_overrides(args.set)
    if overrides is None:
        return 2
    if args.goal is not None:
        from cbp.goals import recorded_goal_overrides

        try:
            overrides = {**recorded_goal_overrides(args.goal), **overrides}
        except CbpError as exc:
            print(f"--goal: {exc}", file=sys.stderr)
            return 2
    names = [m.strip() for m in args.methods.split(",") if m.strip()]
    try:
        result = compare(
            args.scenario,
            names,
            args.out,
            jobs=args.jobs,
            overrides=overrides,
            progress=True,
        )
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    for name, m in result.metrics.items():
        print(
            f"{name:>3}: reached {m.get('reached')!s:5}  total "
            f"{_num(m.get('total_time_s'))} s  peak force "
            f"{_num(m.get('peak_contact_force_n'))} N"
        )
    print(f"Report: {result.out / 'report.md'}")
    from cbp.run.faults import EXIT_ABORTED, EXIT_INCOMPLETE

    aborted = [name for name, m in result.metrics.items() if m.get("aborted")]
    if aborted:
        print(f"aborted: {', '.join(aborted)} (see the report)", file=sys.stderr)
        return EXIT_ABORTED
    incomplete = [name for name, m in result.metrics.items() if m.get("incomplete")]
    if incomplete:
        print(
            f"outputs incomplete: {', '.join(incomplete)} (see metrics.json)",
            file=sys.stderr,
        )
        return EXIT_INCOMPLETE
    return 0


def _num(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.1f}"


RUN = Command(
    "run", "run a scenario headless and write its outputs", _run, _run_arguments
)
COMPARE = Command(
    "compare",
    "run several methods on one recorded goal stream; one report",
    _compare,
    _compare_arguments,
)
