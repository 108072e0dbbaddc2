# SPDX-License-Identifier: Apache-2.0
"""The ``cbp`` command: a table of subcommands, one module per family.

Each module declares its commands as :class:`~cbp.cli.command.Command` rows
(name, help, arguments, handler); :data:`COMMANDS` lists them in the order
``cbp --help`` shows, and :func:`main` reads it.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence

from cbp.cli.bench import BENCH
from cbp.cli.check import CHECK
from cbp.cli.command import Command
from cbp.cli.examples import EXAMPLES
from cbp.cli.plugins import PLUGINS
from cbp.cli.robot import ROBOT, ROBOT_PAIRS
from cbp.cli.run import COMPARE, RUN
from cbp.cli.scenes import SCENES
from cbp.cli.sweep import SWEEP
from cbp.cli.teleop import TELEOP
from cbp.cli.view import VIEW

__all__ = ["COMMANDS", "Command", "build_parser", "main"]

#: Every command of ``cbp``, in the order its help lists them.
COMMANDS: tuple[Command, ...] = (
    RUN,
    COMPARE,
    BENCH,
    CHECK,
    PLUGINS,
    ROBOT_PAIRS,
    SCENES,
    ROBOT,
    VIEW,
    TELEOP,
    EXAMPLES,
    SWEEP,
)

EPILOG = (
    "exit status: 0 done; 1 a sweep had runs not ok (failed or raised; "
    "see its report), or a run's output folder was taken meanwhile; 2 bad "
    "input, found before anything ran; 3 a run was aborted after repeated "
    "faults (its outputs are written, the reason is in metrics.json); 4 a "
    "stage after the run failed (clearance, metrics, plots or the report: "
    "the rest is written, metrics.json names it); 130 interrupted."
)


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``cbp``: its options, then a subparser per row of COMMANDS."""
    parser = argparse.ArgumentParser(
        prog="cbp",
        description="Constraint-based robot control: run and check scenarios.",
        epilog=EPILOG,
    )
    parser.add_argument("--version", action="version", version=f"cbp {_version()}")
    noise = parser.add_mutually_exclusive_group()
    noise.add_argument(
        "-q", "--quiet", action="store_true", help="log errors only (no warnings)"
    )
    noise.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="also every event of a run as it happens (logging at INFO)",
    )
    commands = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add_to(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cbp`` and ``python -m cbp``; returns the exit status."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.ERROR
        if args.quiet
        else logging.INFO
        if args.verbose
        else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    status: int = args.handle(args)
    return status


def _version() -> str:
    """The installed distribution's version."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("cbp")
    except PackageNotFoundError:
        return "(not installed)"
