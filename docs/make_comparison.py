"""Compare the methods on every CAT scene; print docs/comparison.md's tables.

Run: .venv/bin/python docs/make_comparison.py [--out out/comparison] [--figures]
     [--methods cat,hybrid,ik,mp,jt] [--source ground_truth|depth_camera]
(each scene's report.md, metrics.json, traces and plots go under --out;
--figures also copies the tracking and contact-force plots into docs/comparison/).
The second table lists, for the methods that plan (hybrid, MP), the plans per
scene and their mean joint-space length and duration.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from make_cat_scenes import SCENES  # the same scenes, in the paper's order

from cbp.compare import compare

ROOT = Path(__file__).parents[1]
METHODS = ("cat", "hybrid", "ik", "mp", "jt")


def _f(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def main() -> None:
    """Run the comparisons and print one table row per scene."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "comparison")
    parser.add_argument("--figures", action="store_true")
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--source", default="ground_truth")
    args = parser.parse_args()
    methods = args.methods.split(",")
    planners = [m for m in methods if m in ("hybrid", "mp")]
    header = "| scene | " + " | ".join(methods) + " |"
    rule = "|---|" + "---|" * len(methods)
    rows, plans = [], []
    for scene in SCENES:
        result = compare(
            ROOT / "scenarios" / f"cat_{scene}.yaml",
            methods,
            args.out / args.source / scene,
            overrides={"perception.source": args.source},
        )
        cells = []
        for m in methods:
            x = result.metrics[m]
            reached = "reached" if x["reached"] else "not reached"
            cells.append(
                f"{reached}; {_f(x['response_time_s'])} / {_f(x['total_time_s'])} s; "
                f"{x['peak_contact_force_n']:.0f} N"
            )
        rows.append(f"| {scene} | " + " | ".join(cells) + " |")
        print(rows[-1], flush=True)
        cells = []
        for m in planners:
            x = result.metrics[m]
            n = int(x["plans"])
            mean = (
                f"{x['plan_path_length_rad'] / n:.2f} rad, "
                f"{x['plan_duration_s'] / n:.2f} s"
                if n
                else "-"
            )
            cells.append(f"{n}; {mean}")
        plans.append(f"| {scene} | " + " | ".join(cells) + " |")
        if args.figures:
            target = ROOT / "docs" / "comparison"
            target.mkdir(exist_ok=True)
            for name in ("tracking", "contact_force"):
                shutil.copy(result.out / f"{name}.png", target / f"{scene}_{name}.png")
    print("\n".join([header, rule, *rows]))
    print()
    print(
        "| scene | "
        + " | ".join(f"{m}: plans; mean length, duration" for m in planners)
        + " |"
    )
    print("|---|" + "---|" * len(planners))
    print("\n".join(plans))


if __name__ == "__main__":
    main()
