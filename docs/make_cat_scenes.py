"""Run every CAT scene with both obstacle sources; print docs/cat_scenes.md's table.

Run: .venv/bin/python docs/make_cat_scenes.py [--runs 5] [--out out/cat_scenes]
(each run's trace.csv, metrics.json, plots and report.md go under
--out/SOURCE/SCENE/run_K). Medians over the runs, except where the column
says worst, lowest or most.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from cbp.executors.cat import run_cat
from cbp.report import write_outputs
from cbp.scenario import load_scenario

ROOT = Path(__file__).parents[1]
SCENES = [
    "free_step",
    "free_continuous",
    "boards",
    "local_minimum",
    "wrist_limit",
    "unreachable",
    "shelf_reach",
    "shelf_retreat",
]


def _f(value: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if value is None else f"{value * scale:.{digits}f}"


def _median(values: list[float | None]) -> float | None:
    kept = [v for v in values if v is not None]
    return float(np.median(kept)) if kept else None


def main() -> None:
    """Run the scenes ``--runs`` times each; print one table row per scene and source.

    Runs differ: the command period's budget is wall-clock time, so the steps
    per period, and with cameras the frames the map has integrated when, vary
    from run to run.
    """
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "cat_scenes")
    parser.add_argument("--runs", type=int, default=5, help="runs per scene and source")
    args = parser.parse_args()
    print(
        f"| scene | obstacles | reached (of {args.runs}) | response s | total s | "
        "final error cm | worst peak force N | lowest min clearance mm | "
        "steps per period | most deadline misses |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for source in ("ground_truth", "depth_camera"):
        for scene in SCENES:
            runs = []
            for k in range(args.runs):
                scenario = load_scenario(
                    ROOT / "scenarios" / f"cat_{scene}.yaml",
                    overrides={"perception.source": source},
                )
                trace = run_cat(scenario)
                folder = args.out / source / scene / f"run_{k + 1}"
                runs.append(write_outputs(scenario, {"cat": trace}, folder)["cat"])
            reached = sum(bool(m["reached"]) for m in runs)
            print(
                f"| {scene} | {source} | {reached} | "
                f"{_f(_median([m['response_time_s'] for m in runs]))} | "
                f"{_f(_median([m['total_time_s'] for m in runs]))} | "
                f"{_f(_median([m['final_position_error_m'] for m in runs]), 100, 1)} | "
                f"{max(m['peak_contact_force_n'] for m in runs):.0f} | "
                f"{_f(min(m['min_clearance_m'] for m in runs), 1000, 1)} | "
                f"{_median([m['steps_per_period_median'] for m in runs]):.0f} | "
                f"{max(m['deadline_misses'] for m in runs)} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
