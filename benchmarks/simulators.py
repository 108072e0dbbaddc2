"""The CAT paper's eight scenes on each simulator: the same outcome, and its cost.

Each scene is run by CAT on the virtual clock (the same outcome on any
machine and load) with the declared objects, once per simulator, each run
in a process of its own. The table gives, per scene and simulator: reached
or not, the peak contact force, the final distance to the goal, and the CPU
seconds the run took per simulated second (the run alone: loading the
scenario and importing are left out).

Run: PYTHONPATH=. .venv/bin/python -m benchmarks.simulators
     [--scenes free_step,boards] [--simulators pybullet,mujoco]
     [--source declared|cameras]
Prints a markdown table.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from benchmarks.perception_tax import CAT_SCENES

ROOT = Path(__file__).resolve().parents[1]
SIMULATORS = ("pybullet", "mujoco")


def one(path: Path, simulator: str, source: str) -> dict[str, Any]:
    """One CAT run of ``path`` on ``simulator``, virtual clock, as a record."""
    from cbp.executors import load_executor
    from cbp.metrics import run_metrics
    from cbp.scenario import load_scenario

    overrides = {
        "simulator": simulator,
        "method.name": "cat",
        "method.cat.timing.clock": "virtual",
        "perception.source": "ground_truth" if source == "declared" else "depth_camera",
    }
    scenario = load_scenario(path, overrides=overrides)
    cpu = time.process_time()
    trace = load_executor("cat")(scenario, False)
    cpu = time.process_time() - cpu
    m = run_metrics(trace, scenario.robot)
    error = m.get("final_position_error_m")
    return {
        "scene": path.stem,
        "simulator": simulator,
        "source": source,
        "reached": bool(m["reached"]),
        "peak_n": round(float(m.get("peak_contact_force_n") or 0.0), 1),
        "final_mm": None if error is None else round(1e3 * error, 1),
        "cpu_per_s": round(cpu / scenario.spec.duration, 3),
        "events": len(trace.events),
    }


def spawn(path: Path, simulator: str, source: str) -> dict[str, Any]:
    """:func:`one` in a process of its own."""
    command = [sys.executable, "-m", "benchmarks.simulators", "--one", str(path)]
    command += ["--simulators", simulator, "--source", source]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(command, capture_output=True, text=True, env=env, cwd=ROOT)
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or ["no output"]
        return {"scene": path.stem, "simulator": simulator, "error": tail[0]}
    record: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return record


def table(records: list[dict[str, Any]], simulators: list[str]) -> str:
    """The markdown table: one row per scene, one column group per simulator."""
    head = "| scene |" + "".join(
        f" {s}: reached | peak [N] | final [mm] | CPU s / s |" for s in simulators
    )
    rule = "|---|" + "---|---|---|---|" * len(simulators)
    by = {(r["scene"], r["simulator"]): r for r in records}
    rows = [head, rule]
    for scene in dict.fromkeys(r["scene"] for r in records):
        cells = []
        for s in simulators:
            r = by.get((scene, s))
            if r is None or "error" in r:
                why = "not run" if r is None else r["error"]
                cells.append(f" {why} | | | |")
                continue
            reached = "yes" if r["reached"] else "no"
            cells.append(
                f" {reached} | {r['peak_n']:g} | {r['final_mm']} | {r['cpu_per_s']:.2f} |"
            )
        rows.append(f"| {scene} |" + "".join(cells))
    return "\n".join(rows)


def main() -> None:
    """Run the scenes on each simulator (or one run, ``--one``); print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(CAT_SCENES))
    parser.add_argument("--simulators", default=",".join(SIMULATORS))
    parser.add_argument("--source", default="declared", choices=["declared", "cameras"])
    parser.add_argument("--one", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one is not None:
        print(json.dumps(one(args.one, args.simulators, args.source)))
        return
    simulators = args.simulators.split(",")
    records = []
    for scene in args.scenes.split(","):
        path = ROOT / "scenarios" / f"cat_{scene}.yaml"
        for simulator in simulators:
            records.append(spawn(path, simulator, args.source))
            print(json.dumps(records[-1]), file=sys.stderr, flush=True)
    print(table(records, simulators))


if __name__ == "__main__":
    main()
