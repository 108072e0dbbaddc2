"""The compiled contact query against declared objects: before and after.

Two measurements, each a set of rows timed in alternating rounds in one process
(only ratios within one run are meaningful on a shared machine):

1. the CAT step on the boards and its parts (engine step with contact rows,
   contact query and validation) beside the hand-written reaching step, in
   this checkout and, with ``--before PATH``, in another one (an earlier
   commit's, run in a subprocess with that checkout first on the path);
2. ``cbp bench``'s "narrow phase" rows: the compiled narrow phase and coal's,
   side by side in this checkout (``collision.narrow_phase``).

Run (from the repository; ``--before``: e.g. ``git archive`` of the earlier
commit unpacked in a folder):

    PYTHONPATH=. .venv/bin/python benchmarks/narrow_phase.py
        --before /path/to/old/checkout --append benchmarks/RESULTS.md
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: The breakdown's rows, in order; the first is the base of the ratios.
BREAKDOWN = [
    "hand-written reaching step",
    "CAT step on the boards",
    "engine step with contact rows (contacts cached)",
    "contact query and validation (CollisionWorld.check)",
]


def breakdown(repetitions: int) -> dict[str, Any]:
    """The CAT step and its parts beside the hand-written step (this checkout).

    Through the library's public interface and what ``benchmarks/bench.py``
    has made public for long (the hand-written step, the goals, the timing),
    so that an earlier checkout runs it too: the CAT step as ``cbp bench``
    times it, from 2 cm above the first board toward the goal stream's last
    pose, back at the start every 32 steps.
    """
    import pinocchio as pin

    from benchmarks.bench import GOALS, SCENARIOS, HandWritten, measure_interleaved
    from cbp.executors.ik_search import IkSearch
    from cbp.methods.settings import IkSearchSettings
    from cbp.robot import RobotModel
    from cbp.run.budget import WallBudget
    from cbp.scenario import load_scenario

    robot = RobotModel.load("franka_panda")
    hand = HandWritten(robot)
    current = {"q": robot.home()}

    def hand_step(i: int) -> object:
        hand.goal = GOALS[(i // 64) % len(GOALS)]
        dq = hand.step(current["q"])
        current["q"] = pin.integrate(robot.model, current["q"], dq)
        return dq

    def boards() -> Any:
        scenario: Any = load_scenario(SCENARIOS / "cat_boards.yaml")
        search = IkSearch(scenario.robot, "panda_hand", None, IkSearchSettings())
        above = pin.SE3(
            pin.rpy.rpyToMatrix(np.pi, 0.0, np.pi / 2), np.array([0.5, -0.24, 0.19])
        )
        q = search.solve(above, scenario.q0, WallBudget(2.0))
        if q is not None:
            scenario.q0[:] = q
        stream = scenario.goal_stream()
        goal = stream.pose(stream.end_time)
        scenario.goal_task().set_target(goal.translation, goal.rotation)
        return scenario

    moving = boards()
    world = moving.world_for_run()
    engine = moving.make_engine()
    start = moving.q0.copy()
    at = {"q": start}

    def cat_step(i: int) -> object:
        q = start if i % 32 == 0 else at["q"]
        dq = engine.step(q, 0.02).dq
        q_new = moving.robot.integrate(q, dq)
        at["q"] = q_new if world.try_step(q_new).accepted else q
        return dq

    fixed = boards()
    fixed_world = fixed.world_for_run()
    fixed_engine = fixed.make_engine()
    near = fixed.q0
    pair = (near, near + 1e-9)
    fixed_world.check(near)
    functions = [
        hand_step,
        cat_step,
        lambda i: fixed_engine.step(near, 0.02),
        lambda i: fixed_world.check(pair[i % 2]),
    ]
    timed = measure_interleaved(functions, repetitions, 50)
    return {
        "medians": [median for median, _ in timed],
        "load": os.getloadavg()[0],
    }


def breakdown_in(checkout: Path, repetitions: int) -> dict[str, Any]:
    """:func:`breakdown` in another checkout, in a subprocess."""
    code = (
        "import json, sys; sys.path.insert(0, sys.argv[1]); "
        "sys.path.insert(1, sys.argv[2]); "
        "import narrow_phase; "
        "print(json.dumps(narrow_phase.breakdown(int(sys.argv[3]))))"
    )
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            code,
            str(checkout),
            str(ROOT / "benchmarks"),
            str(repetitions),
        ],
        capture_output=True,
        text=True,
        check=True,
        cwd=checkout,
        env={**os.environ, "PYTHONPATH": str(checkout)},
    )
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


def _breakdown_table(runs: list[tuple[str, dict[str, Any]]]) -> list[str]:
    lines = [
        "| case | " + " | ".join(f"{name} us | ratio" for name, _ in runs) + " |",
        "|---|" + "---:|---:|" * len(runs),
    ]
    for k, case in enumerate(BREAKDOWN):
        cells = []
        for _, run in runs:
            medians = run["medians"]
            cells.append(f"{medians[k]:.1f} | {medians[k] / medians[0]:.2f}x")
        lines.append(f"| {case} | " + " | ".join(cells) + " |")
    loads = ", ".join(f"{name} {run['load']:.1f}" for name, run in runs)
    return [*lines, "", f"Load average (1 min) during the runs: {loads}.", ""]


def main() -> None:
    """Measure, print, and with ``--append`` put the section into RESULTS.md."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--before", type=Path, help="an earlier checkout")
    parser.add_argument("--repetitions", type=int, default=2000)
    parser.add_argument("--append", type=Path)
    args = parser.parse_args()
    from results_file import publish  # this folder

    from benchmarks.bench import BenchConfig, narrow_phase_rows

    runs = []
    if args.before is not None:
        runs.append(("before", breakdown_in(args.before, args.repetitions)))
    runs.append(("after", breakdown(args.repetitions)))
    rows = narrow_phase_rows(BenchConfig(repetitions=args.repetitions))
    lines = [
        "## Contact query against declared objects: compiled narrow phase",
        "",
        "Generated by `PYTHONPATH=. .venv/bin/python benchmarks/narrow_phase.py "
        "--before <checkout of the earlier commit> --append benchmarks/RESULTS.md`. "
        "The CAT step on the boards and its parts, each table timed in "
        "alternating rounds in one process; ratios to the hand-written step "
        "of the same run.",
        "",
        *_breakdown_table(runs),
        "The same run, `cbp bench`'s narrow phase rows (coal's narrow phase is "
        "the previous path: coal called from Python per pair):",
        "",
        "| case | median us | ratio |",
        "|---|---:|---|",
    ]
    for row in rows:
        ratio = f"{row.ratio:.2f}x {row.ratio_to}" if row.ratio is not None else ""
        lines.append(f"| {row.case} | {row.median_us:.1f} | {ratio} |")
    text = "\n".join(lines) + "\n"
    publish(text, args.append)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    main()
