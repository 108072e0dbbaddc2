"""The CAT paper's eight scenes on each simulator: the same outcome, and its cost.

Each scene is run by CAT (or ``--method``) on the virtual clock (the same outcome on any
machine and load) with the declared objects, once per simulator, each run
in a process of its own. The table gives, per scene and simulator: reached
or not, the peak contact force, the final distance to the goal, and the CPU
seconds the run took per simulated second (the run alone: loading the
scenario and importing are left out). Against the first simulator,
``apart`` is the largest difference of any joint's position at the same
time of the two runs [mrad].

``--physics`` measures the engines' own cost instead: per scene, CPU
milliseconds per simulated second of its simulation holding the arm at its
start (no planner), the simulators taking turns in one process, the least
of five. ``--contact`` measures contact: the Panda's hand pushed down into a
box (joint 2 commanded 0.5 rad past the home pose, through the box's top
face), as ``tests/sim/test_simulation.py`` pushes it, on each simulator: the
peak and settled contact force, the hand's share, the deepest penetration.

Run: PYTHONPATH=. .venv/bin/python -m benchmarks.simulators
     [--scenes free_step,boards] [--simulators pybullet,mujoco]
     [--source declared|cameras] [--method cat] [--physics] [--contact]
Prints a markdown table.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.perception_tax import CAT_SCENES, CLOCKED

ROOT = Path(__file__).resolve().parents[1]
SIMULATORS = ("pybullet", "mujoco")


def one(
    path: Path, simulator: str, source: str, q_out: Path, method: str = "cat"
) -> dict[str, Any]:
    """One run of ``path`` by ``method`` on ``simulator``, virtual clock, as a record.

    The run's joint positions are saved to ``q_out`` (``.npy``).
    """
    from cbp.executors import load_executor
    from cbp.metrics import run_metrics
    from cbp.scenario import load_scenario

    overrides = {
        "simulator": simulator,
        "method.name": method,
        **{f"method.{m}.timing.clock": "virtual" for m in CLOCKED},
        "perception.source": "ground_truth" if source == "declared" else "depth_camera",
    }
    scenario = load_scenario(path, overrides=overrides)
    cpu = time.process_time()
    trace = load_executor(method)(scenario, False)
    cpu = time.process_time() - cpu
    m = run_metrics(trace, scenario.robot)
    error = m.get("final_position_error_m")
    np.save(q_out, trace.q)
    return {
        "scene": path.stem,
        "simulator": simulator,
        "source": source,
        "reached": bool(m["reached"]),
        "peak_n": round(float(m.get("peak_contact_force_n") or 0.0), 1),
        "final_mm": None if error is None else round(1e3 * error, 1),
        "cpu_per_s": round(cpu / scenario.spec.duration, 3),
        "events": len(trace.events),
        "q": str(q_out),
    }


def spawn(
    path: Path, simulator: str, source: str, folder: Path, method: str
) -> dict[str, Any]:
    """:func:`one` in a process of its own, its joint positions saved in ``folder``."""
    command = [sys.executable, "-m", "benchmarks.simulators", "--one", str(path)]
    command += ["--simulators", simulator, "--source", source, "--method", method]
    command += ["--q-out", str(folder / f"{path.stem}_{simulator}.npy")]
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
        f" {s}: reached | peak [N] | final [mm] | CPU s / s |"
        + (" apart [mrad] |" if k else "")
        for k, s in enumerate(simulators)
    )
    rule = "|---|" + "".join("---|" * (5 if k else 4) for k in range(len(simulators)))
    by = {(r["scene"], r["simulator"]): r for r in records}
    rows = [head, rule]
    for scene in dict.fromkeys(r["scene"] for r in records):
        cells = []
        first = by.get((scene, simulators[0]), {})
        for k, s in enumerate(simulators):
            r = by.get((scene, s))
            if r is None or "error" in r:
                why = "not run" if r is None else r["error"]
                cells.append(f" {why} |" + " |" * (4 if k else 3))
                continue
            reached = "yes" if r["reached"] else "no"
            cells.append(
                f" {reached} | {r['peak_n']:g} | {r['final_mm']} "
                f"| {r['cpu_per_s']:.2f} |"
            )
            if k:
                cells.append(f" {_apart(first, r)} |")
        rows.append(f"| {scene} |" + "".join(cells))
    return "\n".join(rows)


def _apart(a: dict[str, Any], b: dict[str, Any]) -> str:
    """The largest joint position difference of two runs at the same times [mrad]."""
    if "q" not in a or "q" not in b:
        return ""
    qa, qb = np.load(a["q"]), np.load(b["q"])
    n = min(len(qa), len(qb))
    return f"{1e3 * float(np.max(np.abs(qa[:n] - qb[:n]))):.2g}"


def contact(simulators: list[str]) -> str:
    """The hand pushed into a box on each simulator, as a markdown table."""
    from cbp.robot import RobotModel
    from cbp.scenario.scene import ObjectSpec
    from cbp.sim.simulation import Simulation
    from cbp.sim.trajectory import time_parameterize
    from cbp.spatial import Pose

    panda = RobotModel.load("franka_panda")
    box = ObjectSpec(
        name="box",
        shape="box",
        size=(0.3, 0.3, 0.3),
        pose=Pose(position=(0.35, 0, 0.3)),
    )
    q0 = panda.home()
    q1 = q0.copy()
    q1[1] += 0.5
    vmax, amax = 0.3 * panda.velocity_limits, 0.3 * panda.acceleration_limits
    traj = time_parameterize(np.linspace(q0, q1, 50), 0.0, 0 * q0, 0 * q0, vmax, amax)
    assert traj is not None
    rows = [
        "| simulator | peak force [N] | settled [N] | hand's share at peak [N] "
        "| deepest penetration [mm] |",
        "|---|---|---|---|---|",
    ]
    for simulator in simulators:
        with Simulation(panda, [box], q0, simulator=simulator) as sim:
            sim.follow(traj)
            sim.run_until(traj.end_time + 0.5)
            rec = sim.recording()
        peak = int(np.argmax(rec["contact_force"]))
        rows.append(
            f"| {simulator} | {rec['contact_force'][peak]:.0f} "
            f"| {rec['contact_force'][-1]:.0f} | {rec['wrist_force'][peak]:.0f} "
            f"| {1e3 * rec['penetration'].max():.1f} |"
        )
    return "\n".join(rows)


def physics(scenes: list[str], simulators: list[str], repeats: int = 5) -> str:
    """The engines' own cost per scene, as a markdown table.

    Each scene's simulation holds the arm at its start for 1 s (the engine
    and the torque law, no planner), the simulators taking turns in this
    process, ``repeats`` times; the least CPU time of each counts (the
    least disturbed by other work on the machine).
    """
    from cbp.scenario import load_scenario
    from cbp.sim.scene import simulate
    from cbp.sim.simulation import Simulation

    rows = [
        "| scene |" + "".join(f" {s} [ms / s] |" for s in simulators) + " ratio |",
        "|---|" + "---|" * (len(simulators) + 1),
    ]
    totals = dict.fromkeys(simulators, 0.0)
    for scene in scenes:
        costs: dict[str, list[float]] = {s: [] for s in simulators}
        for _ in range(repeats):
            for s in simulators:
                path = ROOT / "scenarios" / f"cat_{scene}.yaml"
                scenario = load_scenario(path, overrides={"simulator": s})
                with simulate(Simulation, scenario) as sim:
                    cpu = time.process_time()
                    sim.run_until(1.0)
                    costs[s].append(time.process_time() - cpu)
        least = {s: min(c) for s, c in costs.items()}
        for s in simulators:
            totals[s] += least[s]
        cells = "".join(f" {1e3 * least[s]:.1f} |" for s in simulators)
        ratio = least[simulators[-1]] / least[simulators[0]]
        rows.append(f"| cat_{scene} |{cells} {ratio:.2f} |")
    ratio = totals[simulators[-1]] / totals[simulators[0]]
    rows.append("| all |" + " |" * len(simulators) + f" {ratio:.2f} |")
    return "\n".join(rows)


def main() -> None:
    """Run the scenes on each simulator (or one run, ``--one``); print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(CAT_SCENES))
    parser.add_argument("--simulators", default=",".join(SIMULATORS))
    parser.add_argument("--source", default="declared", choices=["declared", "cameras"])
    parser.add_argument("--method", default="cat", help="cat, ik, mp, hybrid, jt")
    parser.add_argument("--contact", action="store_true", help="the contact probe")
    parser.add_argument("--physics", action="store_true", help="the engines' cost")
    parser.add_argument("--one", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--q-out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one is not None:
        record = one(args.one, args.simulators, args.source, args.q_out, args.method)
        print(json.dumps(record))
        return
    simulators = args.simulators.split(",")
    if args.contact:
        print(contact(simulators))
        return
    if args.physics:
        print(physics(args.scenes.split(","), simulators))
        return
    records = []
    folder = Path(tempfile.mkdtemp(prefix="cbp_simulators_"))
    for scene in args.scenes.split(","):
        path = ROOT / "scenarios" / f"cat_{scene}.yaml"
        for simulator in simulators:
            records.append(spawn(path, simulator, args.source, folder, args.method))
            print(json.dumps(records[-1]), file=sys.stderr, flush=True)
    print(table(records, simulators))
    shutil.rmtree(folder)


if __name__ == "__main__":
    main()
