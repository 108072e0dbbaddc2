# SPDX-License-Identifier: Apache-2.0
"""``cbp run`` and ``cbp compare``: one method, or several on one goal stream."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cbp.cli.command import Command, add_set, read_overrides
from cbp.errors import CbpError, ConfigError
from cbp.methods import COMPARABLE, METHODS

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
    from cbp.report import summary_line, write_outputs
    from cbp.run.faults import EXIT_ABORTED, EXIT_INCOMPLETE, stop_on_signals

    try:
        claim = claim_output_folder(out)  # refused if a live run writes there
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    from cbp.progress import run_progress

    try:
        # SIGINT, SIGTERM, SIGHUP: the run brakes and its outputs are written.
        with run_progress(f"{scenario.spec.name} ({name})"), stop_on_signals():
            trace = executor(scenario, args.gui)
    except ConfigError as exc:  # found as the run starts (a URDF PyBullet refuses)
        claim.release(remove=True)
        print(exc, file=sys.stderr)
        return 2
    except BaseException:
        claim.release(remove=True)
        raise
    try:
        metrics = write_outputs(scenario, {name: trace}, out, claim=claim)[name]
    except CbpError as exc:  # the folder changed during the run; outputs kept
        print(exc, file=sys.stderr)
        return 1
    print(summary_line(scenario, name, metrics))
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
