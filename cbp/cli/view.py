# SPDX-License-Identifier: Apache-2.0
"""``cbp view``: replay a finished run (or a comparison) in the browser."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cbp.cli.command import Command, missing_extra
from cbp.errors import CbpError

__all__ = ["VIEW"]


def _arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", type=Path, help="the run's output folder")
    parser.add_argument("--port", type=int, default=8080)
    parser.add_argument(
        "--export", type=Path, default=None, help="write a .viser recording instead"
    )


def _view(args: argparse.Namespace) -> int:
    if missing_extra("view", "viewer"):
        return 2
    from cbp.viewer import serve

    try:
        return serve(args.out, args.port, args.export)
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return 2


VIEW = Command(
    "view",
    "replay a finished run (or a comparison) in the browser",
    _view,
    _arguments,
)
