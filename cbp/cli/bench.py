# SPDX-License-Identifier: Apache-2.0
"""``cbp bench``: the benchmark harness of a source checkout."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cbp.cli.command import Command

__all__ = ["BENCH"]


def _arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--out", type=Path, default=None, help="write the rows as JSON")
    parser.add_argument(
        "--results", type=Path, default=None, help="write a RESULTS.md table there"
    )


def _bench(args: argparse.Namespace) -> int:
    """Run the benchmark harness of the source checkout (``benchmarks/bench.py``).

    The harness is not part of the installed package: it times peers (pink,
    mink, placo) and scenes that only the repository has.
    """
    import importlib.util

    harness = Path(__file__).resolve().parents[2] / "benchmarks" / "bench.py"
    spec = importlib.util.spec_from_file_location("cbp_benchmarks_bench", harness)
    if not harness.is_file() or spec is None or spec.loader is None:
        print(
            f"cbp bench runs the benchmark harness of a source checkout "
            f"({harness} is missing): clone the repository and install it with "
            "'pip install -e .[bench]'",
            file=sys.stderr,
        )
        return 2
    bench = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = bench  # dataclasses look their module up
    spec.loader.exec_module(bench)
    config = bench.BenchConfig.quick() if args.quick else bench.BenchConfig()
    result = bench.run_bench(
        config, progress=lambda row: print(bench.format_row(row), flush=True)
    )
    print("profile of the CAT step (largest own-time shares):")
    for name, pct in result["profile_cat_step"]:
        print(f"  {name}: {pct:.0f} %")
    print("\n".join(bench.targets_table(result["rows"])), flush=True)
    if args.out is not None:
        bench.dump(result, args.out)
    if args.results is not None:
        flags = " --quick" if args.quick else ""
        command = f"cbp bench{flags} --results {args.results}"
        bench.write_results(result, args.results, command)
    return 0


BENCH = Command(
    "bench", "time the engine, CAT, MP, orbit and map rows", _bench, _arguments
)
