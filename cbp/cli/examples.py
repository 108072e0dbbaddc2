# SPDX-License-Identifier: Apache-2.0
"""``cbp examples``: copy the example scenarios out to edit."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cbp.cli.command import Command

__all__ = ["EXAMPLES", "FIRST_EXAMPLE"]

#: The example ``cbp examples`` suggests running first: CAT reaches across
#: three boards without touching them (the demo's scenario).
FIRST_EXAMPLE = "cat_boards.yaml"


def _arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", type=Path, nargs="?", default=Path("cbp_examples"))


def _examples(args: argparse.Namespace) -> int:
    import shutil

    from cbp.data import data_dir

    out: Path = args.out
    if out.exists() and any(out.iterdir()):
        print(f"{out} is not empty; choose a new folder", file=sys.stderr)
        return 2
    shutil.copytree(
        data_dir("scenarios"), out, ignore=shutil.ignore_patterns("__pycache__")
    )
    names = sorted(p.name for p in out.glob("*.yaml"))
    print(f"copied {len(names)} scenarios (and configs/, sweeps/) to {out}:")
    for name in names:
        print(f"  {name}")
    if FIRST_EXAMPLE in names:
        print(
            f"run one with: cbp run {out / FIRST_EXAMPLE} (CAT over three boards, "
            "without touching them)"
        )
    return 0


EXAMPLES = Command(
    "examples",
    "copy the example scenarios (and configs) out to edit",
    _examples,
    _arguments,
)
