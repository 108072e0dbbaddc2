"""Soak: CAT for minutes of random goals in clutter, watched for drift.

A generated cluttered scene (:mod:`cbp.scenes`, seeded) with a random goal
stream (a new goal every 2-4 s among the objects; some lie inside or behind
them, where the arm must stop short) runs with CAT for ``--minutes`` of
simulated time, with declared obstacles and with the cameras. While it runs,
the process's resident memory is sampled every few seconds. Reported per
minute of simulated time: peak contact force, events, median QP steps per
period, and memory; and overall: the memory growth after the first minute
(the largest per-minute peak of resident memory after it, against its peak) and
the trend of steps per period (least-squares slope, % per minute).

Steps per period are those of the periods that used their whole budget,
scaled to the nominal period (the work a period fits). Targets (issue 17): no
contact, memory flat within 50 MB after the first minute, no trend in steps
per period.

Run: .venv/bin/python benchmarks/soak.py --minutes 10 --append benchmarks/RESULTS.md
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import yaml
from results_file import publish  # this folder: scripts run from it

from cbp.executors.cat import CatPlanner
from cbp.goals import write_recorded
from cbp.methods.settings import CatSettings
from cbp.metrics import run_metrics
from cbp.run import build_run
from cbp.run.loop import run_loop
from cbp.scenario import load_scenario
from cbp.scenes import HAND_DOWN, REGION, generate_scene
from cbp.trace import FULL_PERIOD_NOTE


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return float(line.split()[1]) / 1024.0
    return float("nan")


def _goal_file(path: Path, duration: float, seed: int) -> None:
    """Random goals among the objects, held 2-4 s each, at 30 Hz."""
    rng = np.random.default_rng(seed)
    rotation = pin.rpy.rpyToMatrix(*np.deg2rad(HAND_DOWN))
    times, positions = [], []
    t = 0.0
    while t < duration:
        goal = [
            rng.uniform(REGION[0][0], 0.7),
            rng.uniform(REGION[0][1], REGION[1][1]),
            rng.uniform(0.12, 0.45),
        ]
        hold = rng.uniform(2.0, 4.0)
        for s in np.arange(t, min(t + hold, duration + 1e-9), 1.0 / 30.0):
            times.append(float(s))
            positions.append(goal)
        t += hold
    write_recorded(path, times, np.array(positions), np.array([rotation] * len(times)))


def soak(minutes: float, source: str, seed: int, folder: Path) -> dict[str, Any]:
    """One soak run; per-minute figures and the overall verdict."""
    duration = minutes * 60.0
    document = generate_scene(seed)
    goal = folder / f"goal_{seed}.csv"
    _goal_file(goal, duration, seed)
    document["duration"] = duration
    document["goal"] = {"type": "recorded", "file": str(goal)}
    path = folder / f"soak_{source}.yaml"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    scenario = load_scenario(path, overrides={"perception.source": source})
    settings = scenario.spec.method.settings(CatSettings)
    run = build_run(scenario, method="cat", clock=settings.timing.clock)
    samples: list[tuple[float, float]] = []  # (simulated time, RSS MB)
    done = threading.Event()

    def watch() -> None:
        while not done.wait(2.0):
            samples.append((run.arm.t, _rss_mb()))

    watcher = threading.Thread(target=watch, daemon=True)
    start = time.perf_counter()
    watcher.start()
    try:
        trace = run_loop(run, CatPlanner(run.scenario, settings), settings.timing)
    finally:
        done.set()
        watcher.join()
    wall = time.perf_counter() - start
    metrics = run_metrics(trace, scenario.robot)
    rows = []
    sim_t = np.array([s[0] for s in samples])
    rss = np.array([s[1] for s in samples])
    # Steps per period of the periods that used their whole budget: the work
    # one period fits (periods that converged early say nothing about speed).
    full = [p for p in trace.periods if p.note == FULL_PERIOD_NOTE]
    period_t = np.array([p.t for p in full])
    steps = np.array([p.steps / p.period for p in full]) * settings.timing.period
    for minute in range(int(np.ceil(minutes))):
        lo, hi = minute * 60.0, (minute + 1) * 60.0
        in_trace = (trace.t >= lo) & (trace.t < hi)
        in_periods = (period_t >= lo) & (period_t < hi)
        in_rss = (sim_t >= lo) & (sim_t < hi)
        assert trace.contact_force is not None
        rows.append(
            {
                "minute": minute + 1,
                "peak_force_n": float(np.max(trace.contact_force[in_trace], initial=0)),
                "events": sum(1 for t, _ in trace.events if lo <= t < hi),
                "steps_median": float(np.median(steps[in_periods]))
                if in_periods.any()
                else float("nan"),
                "rss_mb": float(np.max(rss[in_rss])) if in_rss.any() else float("nan"),
            }
        )
    # Growth: the largest per-minute peak after the first minute, against the
    # first minute's peak (RSS swings by tens of MB within a minute as buffers
    # are freed and taken again; the peaks show what is kept).
    peaks = np.array([r["rss_mb"] for r in rows])
    growth = float(np.nanmax(peaks[1:]) - peaks[0]) if len(peaks) > 1 else 0.0
    medians = np.array([r["steps_median"] for r in rows])
    ok = np.isfinite(medians)
    slope = (
        float(np.polyfit(np.arange(len(medians))[ok], medians[ok], 1)[0])
        if ok.sum() >= 2
        else 0.0
    )
    mean = float(np.mean(medians[ok])) if ok.any() else float("nan")
    return {
        "source": source,
        "wall_s": wall,
        "rows": rows,
        "peak_force_n": metrics["peak_contact_force_n"],
        "events": len(trace.events),
        "aborted": trace.aborted,
        "rss_growth_mb": growth,
        "steps_trend_pct_per_min": 100.0 * slope / mean if mean else float("nan"),
    }


def _markdown(results: list[dict[str, Any]], minutes: float, seed: int) -> str:
    lines = [
        "",
        f"## Soak: {minutes:g} min of random goals in clutter (benchmarks/soak.py)",
        "",
        f"Scene `cbp.scenes` seed {seed}, CAT (wall clock), {platform.processor() or platform.machine()}, "
        f"{platform.python_version()}. "
        f"Command: `.venv/bin/python benchmarks/soak.py --minutes {minutes:g} --seed {seed}`.",
        "",
        "| source | wall [s] | peak force [N] | events | aborted | RSS growth after 1 min [MB] | steps/period trend [%/min] |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in results:
        lines.append(
            f"| {r['source']} | {r['wall_s']:.0f} | {r['peak_force_n']:.1f} | "
            f"{r['events']} | {r['aborted'] or 'no'} | {r['rss_growth_mb']:.1f} | "
            f"{r['steps_trend_pct_per_min']:+.2f} |"
        )
    for r in results:
        lines += [
            "",
            f"Per minute, {r['source']}:",
            "",
            "| minute | peak force [N] | events | median steps/period | RSS [MB] |",
            "|---|---|---|---|---|",
        ]
        lines += [
            f"| {row['minute']} | {row['peak_force_n']:.1f} | {row['events']} | "
            f"{row['steps_median']:.0f} | {row['rss_mb']:.0f} |"
            for row in r["rows"]
        ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument(
        "--sources", default="ground_truth,depth_camera", help="comma-separated"
    )
    parser.add_argument("--append", type=Path, default=None)
    args = parser.parse_args()
    results = []
    with tempfile.TemporaryDirectory(prefix="cbp-soak-") as folder:
        for source in args.sources.split(","):
            result = soak(args.minutes, source, args.seed, Path(folder))
            print(
                f"{source}: {result['wall_s']:.0f} s wall, peak "
                f"{result['peak_force_n']:.1f} N, {result['events']} events, "
                f"RSS growth {result['rss_growth_mb']:.1f} MB, steps trend "
                f"{result['steps_trend_pct_per_min']:+.2f} %/min",
                flush=True,
            )
            results.append(result)
    text = _markdown(results, args.minutes, args.seed)
    publish(text, args.append)


if __name__ == "__main__":
    main()
