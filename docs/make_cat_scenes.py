"""Run every CAT scene with both obstacle sources; print docs/cat_scenes.md's table.

Run: .venv/bin/python docs/make_cat_scenes.py [--out out/cat_scenes]
(each run's trace.csv, metrics.json, plots and report.md go under --out).
"""

from __future__ import annotations

import argparse
from pathlib import Path

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


def main() -> None:
    """Run the scenes and print one table row per run."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "cat_scenes")
    args = parser.parse_args()
    print(
        "| scene | obstacles | reached | response s | total s | final error cm | "
        "peak force N | min clearance mm | steps per period | deadline misses |"
    )
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for source in ("ground_truth", "depth_camera"):
        for scene in SCENES:
            scenario = load_scenario(
                ROOT / "scenarios" / f"cat_{scene}.yaml",
                overrides={"perception.source": source},
            )
            trace = run_cat(scenario)
            folder = args.out / source / scene
            m = write_outputs(scenario, {"cat": trace}, folder)["cat"]
            print(
                f"| {scene} | {source} | {'yes' if m['reached'] else 'no'} | "
                f"{_f(m['response_time_s'])} | {_f(m['total_time_s'])} | "
                f"{_f(m['final_position_error_m'], 100, 1)} | "
                f"{m['peak_contact_force_n']:.0f} | "
                f"{_f(m['min_clearance_m'], 1000, 1)} | "
                f"{m['steps_per_period_median']:.0f} | {m['deadline_misses']} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
