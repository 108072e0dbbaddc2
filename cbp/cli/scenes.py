# SPDX-License-Identifier: Apache-2.0
"""``cbp scenes``: seeded cluttered (or moving) scenes for the Panda."""

from __future__ import annotations

import argparse
from pathlib import Path

from cbp.cli.command import Command, positive_int

__all__ = ["SCENES"]


def _arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--count", type=positive_int, default=30)
    parser.add_argument("--seed", type=int, default=0, help="first seed")
    parser.add_argument("--out", type=Path, default=Path("out/scenes"))
    parser.add_argument(
        "--moving",
        action="store_true",
        help="obstacles that come at a still hand at 2-20 cm/s instead of clutter",
    )
    parser.add_argument(
        "--mbm", type=Path, help="MotionBenchMaker's Panda problems from this checkout"
    )
    parser.add_argument("--family", action="append", help="with --mbm: only these")


def _scenes(args: argparse.Namespace) -> int:
    if args.mbm is not None:
        from cbp.mbm import scenes_command

        return scenes_command(args.mbm, args.out, args.count, args.seed, args.family)
    from cbp.scenes import write_scenes

    for path in write_scenes(args.out, args.count, args.seed, args.moving):
        print(path)
    return 0


SCENES = Command(
    "scenes",
    "write seeded cluttered scenes (scenario files) for the Panda",
    _scenes,
    _arguments,
)
