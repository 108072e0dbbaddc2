"""Compare CAT, IK, MP and JT on every CAT scene; print docs/comparison.md's tables.

Run: .venv/bin/python docs/make_comparison.py [--out out/comparison] [--figures]
(each scene's report.md, metrics.json, traces and plots go under --out;
--figures also copies the tracking and contact-force plots into docs/comparison/).
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from make_cat_scenes import SCENES  # the same scenes, in the paper's order

from cbp.compare import compare

ROOT = Path(__file__).parents[1]
METHODS = ("cat", "ik", "mp", "jt")


def _f(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def main() -> None:
    """Run the comparisons and print one table row per scene."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "comparison")
    parser.add_argument("--figures", action="store_true")
    args = parser.parse_args()
    header = "| scene | " + " | ".join(METHODS) + " |"
    rule = "|---|" + "---|" * len(METHODS)
    rows = []
    for scene in SCENES:
        result = compare(
            ROOT / "scenarios" / f"cat_{scene}.yaml", METHODS, args.out / scene
        )
        cells = []
        for m in METHODS:
            x = result.metrics[m]
            reached = "reached" if x["reached"] else "not reached"
            cells.append(
                f"{reached}; {_f(x['response_time_s'])} / {_f(x['total_time_s'])} s; "
                f"{x['peak_contact_force_n']:.0f} N"
            )
        rows.append(f"| {scene} | " + " | ".join(cells) + " |")
        print(rows[-1], flush=True)
        if args.figures:
            target = ROOT / "docs" / "comparison"
            target.mkdir(exist_ok=True)
            for name in ("tracking", "contact_force"):
                shutil.copy(result.out / f"{name}.png", target / f"{scene}_{name}.png")
    print("\n".join([header, rule, *rows]))


if __name__ == "__main__":
    main()
