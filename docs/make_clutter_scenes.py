"""Run generated cluttered scenes with both obstacle sources; print a table.

Run: .venv/bin/python docs/make_clutter_scenes.py [--count 30] [--seed 0]
     [--out out/clutter]
Scenes come from ``cbp.scenes`` (the files are written under --out/scenes, so
any run can be repeated with ``cbp run``). The table goes to stdout; the summary
in docs/clutter_scenes.md is this script's output.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cbp.executors.cat import run_cat
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario
from cbp.scenes import write_scenes

ROOT = Path(__file__).parents[1]
SOURCES = ("ground_truth", "depth_camera")


def main() -> None:
    """Generate, run and tabulate."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--count", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "clutter")
    args = parser.parse_args()
    paths = write_scenes(args.out / "scenes", args.count, args.seed)
    print("| scene | objects | obstacles | reached | peak force N | events |")
    print("|---|---:|---|---|---:|---:|")
    totals = {s: [0, 0, 0.0] for s in SOURCES}  # reached, runs, worst force
    for path in paths:
        for source in SOURCES:
            scenario = load_scenario(path, overrides={"perception.source": source})
            m = run_metrics(run_cat(scenario))
            total = totals[source]
            total[0] += int(m["reached"])
            total[1] += 1
            total[2] = max(total[2], m["peak_contact_force_n"])
            print(
                f"| {path.stem} | {len(scenario.spec.world.objects) - 1} | {source} "
                f"| {'yes' if m['reached'] else 'no'} | "
                f"{m['peak_contact_force_n']:.0f} | {m['events']} |",
                flush=True,
            )
    print()
    print("| obstacles | runs | reached | worst peak force N |")
    print("|---|---:|---:|---:|")
    for source, (reached, runs, worst) in totals.items():
        print(f"| {source} | {runs} | {reached} | {worst:.0f} |")


if __name__ == "__main__":
    main()
