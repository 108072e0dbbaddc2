# SPDX-License-Identifier: Apache-2.0
"""``cbp sweep``: scenes x methods x settings on Ray or a process pool."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cbp.cli.command import Command, positive_int
from cbp.errors import CbpError

__all__ = ["SWEEP"]


def _arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sweep", type=Path, help="the sweep file (YAML)")
    parser.add_argument("--out", type=Path, default=None, help="default out/<name>")
    parser.add_argument(
        "--workers", type=positive_int, default=None, help="CPUs (default: all)"
    )
    parser.add_argument(
        "--address", default=None, help="join this Ray cluster (ray start --head)"
    )
    parser.add_argument(
        "--backend",
        choices=("auto", "ray", "pool"),
        default="auto",
        help="ray, a process pool, or ray if installed (auto)",
    )


def _sweep(args: argparse.Namespace) -> int:
    from cbp.sweep import load_sweep, run_sweep

    try:
        name = load_sweep(args.sweep).name
        outcome = run_sweep(
            args.sweep,
            args.out or Path("out") / name,
            workers=args.workers,
            address=args.address,
            progress=True,
            backend=args.backend,
        )
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2
    ran = len(outcome.records) - outcome.skipped
    print(
        f"{len(outcome.runs)} runs: {outcome.skipped} already done, {ran} run now "
        f"({outcome.backend}), {outcome.failed} not ok"
    )
    print(f"Report: {outcome.out / 'report.md'}")
    if outcome.interrupted:
        print("interrupted: run the same command again to resume", file=sys.stderr)
        return 130
    if outcome.failed:
        print(
            f"{outcome.failed} of {len(outcome.runs)} runs not ok (see the report)",
            file=sys.stderr,
        )
        return 1
    return 0


SWEEP = Command(
    "sweep",
    "run a sweep file (scenes x methods x settings) on Ray or a process pool",
    _sweep,
    _arguments,
    description="Run a sweep file on Ray or a process pool. A run whose worker "
    "dies is retried (the file's 'retries'), then recorded as failed; a run "
    "that raises is recorded with its error. Exit status 1 when any run is "
    "not ok, 0 when all are; a rerun skips the runs already done.",
)
