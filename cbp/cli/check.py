# SPDX-License-Identifier: Apache-2.0
"""``cbp check``: validate scenario files without running them."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cbp.cli.command import Command, add_set, read_overrides
from cbp.errors import CbpError

__all__ = ["CHECK"]


def _arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenarios", type=Path, nargs="+")
    add_set(parser, "override a value in every scenario checked (as for run)")


def _check(args: argparse.Namespace) -> int:
    from cbp.scenario import load_scenario

    overrides = read_overrides(args.set)
    if overrides is None:
        return 2
    status = 0
    for path in args.scenarios:
        try:
            load_scenario(path, overrides=overrides)
        except CbpError as exc:
            print(exc, file=sys.stderr)
            status = 2
        else:
            print(f"{path}: ok")
    return status


CHECK = Command(
    "check", "validate scenario files without running them", _check, _arguments
)
