"""Where wall-clock runs with cameras lose time: capture to use of each map snapshot.

A CAT run with the cameras (``perception.source: depth_camera``) in a scene
where an obstacle moves, with the map in a thread beside the control loop
(``perception.map_process: false``) or in its own process (the default), and,
for reference, in virtual time (the map takes each frame in the loop).
Measured per run, without changing the library (its functions are wrapped here):

* capture: PyBullet's tiny renderer, in the control process, per frame (wall ms);
* the map: from the frame's submission to the map taking it (waiting),
  integrating it, building the snapshot (and the approach estimate), and
  publishing it to the collision world (wall ms, from the updater's
  :class:`~cbp.perception.mapper.Publication` records);
* use: the first contact query of the control loop against each snapshot.

Capture to use is given in wall time and in the run's simulated time (the
simulation does not run in real time: each command period's planning is
budgeted in wall time, the simulation then advances by the period), with the
number of command periods that passed. Also: QP steps per period, the run's
wall time, peak contact force and events.

Run: .venv/bin/python benchmarks/map_latency.py --runs 3 --append benchmarks/RESULTS.md
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from results_file import put_section  # this folder: scripts run from it

from cbp.collision.map_environment import OccupancyEnvironment
from cbp.collision.world import CollisionWorld
from cbp.executors.cat import run_cat
from cbp.metrics import run_metrics
from cbp.run.cameras import Cameras
from cbp.scenario import load_scenario
from cbp.sim.camera import DepthCamera

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "cat_pushed_obstacle.yaml"

#: The moving-obstacle cases: overrides of ``cat_pushed_obstacle``.
CASES: dict[str, dict[str, str]] = {
    "side 5 cm/s": {},
    "lowered 5 cm/s": {
        "world.objects.box.pose.position": "[0.5, -0.40, 0.52]",
        "world.objects.box.motion": "{velocity: [0.0, 0.0, -0.05], start: 0.5,"
        " stop: 4.5}",
    },
    "side 10 cm/s": {
        "world.objects.box.motion": "{velocity: [0.0, -0.1, 0.0], start: 0.5,"
        " stop: 2.5}",
        "duration": "4.0",
    },
}

#: The map's ways of running: overrides.
MODES: dict[str, dict[str, str]] = {
    "thread": {"perception.map_process": "false"},
    "process": {"perception.map_process": "true"},
    "virtual": {"method.cat.timing.clock": "virtual"},
}


#: How to read the table (the structure of a wall-clock run, not its figures).
READING = """How to read it. A wall-clock run is not a real-time one: each command
period the planner works for its wall-clock budget (0.8 of the period) while
the simulation waits, then the simulation advances a period, rendering each
camera frame that falls due in the control process as it goes (the five
cameras' frames of a time one after the other). A frame taken during the
advance to t can be used by the planning that starts at t at the earliest, so
capture to use in simulated time is at least the rest of that period (virtual
time: 0-33 ms); it grows by a period each time the map has not published the
frame's snapshot before the planner's queries of the next period. The map
works beside the rendering and the planning: in a thread it shares the
interpreter lock with them, in its own process it needs a free core, which a
2-core machine shared with other work does not have. The planner's QP steps per
period show how much of the cores the control loop itself got: virtual time
charges 145 us a step (about 180 a period); fewer steps plan less far per
period, whatever the map does.
"""


class Probe:
    """Wraps the library's functions for one run and keeps what they saw."""

    def __init__(self) -> None:
        """Nothing seen yet."""
        self.run: Cameras | None = None
        self.sim: Any = None
        self.captures: list[tuple[float, float]] = []  # (sim t, wall s)
        self.submits: dict[float, float] = {}  # capture t -> wall at last submit
        self.first: dict[float, float] = {}  # capture t -> wall at first submit
        self.published: dict[int, tuple[float, float, float]] = {}
        self.used: dict[int, tuple[float, float, float]] = {}
        self.kept: list[object] = []
        self.main = threading.main_thread()
        self._saved: list[tuple[Any, str, Any]] = []

    def __enter__(self) -> Probe:
        """Wrap."""
        probe = self
        init = Cameras.__init__
        capture = DepthCamera.capture
        set_environment = CollisionWorld.set_environment
        query = OccupancyEnvironment.query

        def wrapped_init(run: Cameras, *args: Any, **kwargs: Any) -> None:
            probe.run = run
            probe.sim = args[0] if args else kwargs["sim"]
            init(run, *args, **kwargs)
            mapper = run.mapper
            if mapper is not None:
                submit = mapper.submit

                def wrapped_submit(frame: Any, q: Any, t: float = 0.0) -> None:
                    now = time.perf_counter()
                    probe.submits[t] = now  # the last frame taken at t
                    probe.first.setdefault(t, now)
                    submit(frame, q, t)

                mapper.submit = wrapped_submit  # type: ignore[method-assign]

        def wrapped_capture(camera: DepthCamera, *args: Any) -> Any:
            start = time.perf_counter()
            frame = capture(camera, *args)
            if probe.run is not None:
                probe.captures.append((probe.sim.t, time.perf_counter() - start))
            return frame

        def wrapped_set(world: CollisionWorld, environment: Any) -> None:
            set_environment(world, environment)
            stamp = getattr(environment, "stamp", None)
            if stamp is not None and probe.run is not None:
                probe.kept.append(environment)
                probe.published[id(environment)] = (
                    stamp,
                    time.perf_counter(),
                    probe.sim.t,
                )

        def wrapped_query(env: OccupancyEnvironment, *args: Any) -> Any:
            if (
                threading.current_thread() is probe.main
                and id(env) in probe.published
                and id(env) not in probe.used
                and probe.run is not None
            ):
                probe.used[id(env)] = (
                    env.stamp or 0.0,
                    time.perf_counter(),
                    probe.sim.t,
                )
            return query(env, *args)

        for owner, name, new in [
            (Cameras, "__init__", wrapped_init),
            (DepthCamera, "capture", wrapped_capture),
            (CollisionWorld, "set_environment", wrapped_set),
            (OccupancyEnvironment, "query", wrapped_query),
        ]:
            self._saved.append((owner, name, getattr(owner, name)))
            setattr(owner, name, new)
        return self

    def __exit__(self, *exc: object) -> None:
        """Unwrap."""
        for owner, name, old in self._saved:
            setattr(owner, name, old)


def one_run(case: str, mode: str) -> dict[str, Any]:
    """One CAT run of ``case`` with the map run as ``mode``; its figures."""
    overrides = {"perception.source": "depth_camera"} | CASES[case] | MODES[mode]
    scenario = load_scenario(SCENARIO, overrides=overrides)
    with Probe() as probe:
        start = time.perf_counter()
        trace = run_cat(scenario)
        wall = time.perf_counter() - start
    run = probe.run
    assert run is not None
    assert run.mapper is not None
    metrics = run_metrics(trace)
    records = list(run.mapper.published)
    # Per snapshot used by the loop: capture (its newest frame) to first use.
    rows = []
    for stamp, used_wall, used_sim in probe.used.values():
        submitted = probe.submits.get(stamp)
        if submitted is None or stamp <= 0.0:
            continue  # the first look, taken before the loop
        rows.append((used_wall - submitted, used_sim - stamp))
    lat = np.array(rows).reshape(-1, 2)
    # From the first frame taken at a time to the map taking the newest one.
    waits = [
        r.received - probe.first[r.stamp]
        for r in records
        if r.stamp in probe.first and r.stamp > 0
    ]
    periods = trace.periods
    steps = np.array([p.steps for p in periods if not p.missed])
    capture_ms = np.array([c[1] for c in probe.captures]) * 1e3
    out: dict[str, Any] = {
        "case": case,
        "mode": mode,
        "wall_s": wall,
        "sim_s": float(trace.t[-1]),
        "frames": len(probe.captures),
        "capture_ms_median": float(np.median(capture_ms)),
        "capture_s_total": float(capture_ms.sum() / 1e3),
        "snapshots": len(records),
        "snapshots_used": len(lat),
        "wait_ms_median": float(np.median(waits) * 1e3) if waits else None,
        "integrate_ms_median": float(
            np.median([r.integrate_s / max(r.frames, 1) for r in records]) * 1e3
        ),
        "snapshot_ms_median": float(np.median([r.snapshot_s for r in records]) * 1e3),
        "latency_wall_ms": _stats(lat[:, 0] * 1e3),
        "latency_sim_ms": _stats(lat[:, 1] * 1e3),
        "steps_per_period_median": float(np.median(steps)) if len(steps) else 0.0,
        "missed_periods": int(sum(p.missed for p in periods)),
        "periods": len(periods),
        "peak_contact_force_n": float(metrics["peak_contact_force_n"]),
        "events": len(trace.events),
        "aborted": trace.aborted,
        "load": os.getloadavg()[0],
    }
    return out


def _stats(values: np.ndarray) -> dict[str, float] | None:
    if not len(values):
        return None
    return {
        "median": float(np.median(values)),
        "p95": float(np.percentile(values, 95)),
        "max": float(np.max(values)),
    }


def table(results: list[dict[str, Any]]) -> str:
    """The results as a markdown table."""
    head = (
        "| case | map | run wall s / sim s | capture ms (median) | "
        "integrate ms/frame | snapshot ms | capture to use, wall ms: median / p95 | "
        "capture to use, sim ms: median / p95 | QP steps per period | "
        "peak force N | events |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n"
    )
    lines = []
    for r in results:
        w, s = r["latency_wall_ms"] or {}, r["latency_sim_ms"] or {}
        lines.append(
            f"| {r['case']} | {r['mode']} | {r['wall_s']:.0f} / {r['sim_s']:.1f} | "
            f"{r['capture_ms_median']:.0f} | {r['integrate_ms_median']:.1f} | "
            f"{r['snapshot_ms_median']:.1f} | "
            f"{_fmt(w.get('median'))} / {_fmt(w.get('p95'))} | "
            f"{_fmt(s.get('median'))} / {_fmt(s.get('p95'))} | "
            f"{r['steps_per_period_median']:.0f} | "
            f"{r['peak_contact_force_n']:.0f} | {r['events']} |"
        )
    return head + "\n".join(lines) + "\n"


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.0f}"


def main() -> None:
    """Measure; print the table; optionally put it into RESULTS.md."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--case", action="append", choices=list(CASES))
    parser.add_argument("--mode", action="append", choices=list(MODES))
    parser.add_argument("--json", type=Path, help="write every run's figures here")
    parser.add_argument("--append", type=Path, help="put the section into this file")
    parser.add_argument(
        "--from-json", type=Path, help="tabulate a --json file instead of measuring"
    )
    parser.add_argument("--note", help="the load while measured (with --from-json)")
    args = parser.parse_args()
    results = json.loads(args.from_json.read_text()) if args.from_json else []
    for _ in range(0 if args.from_json else args.runs):
        for case in args.case or list(CASES):
            for mode in args.mode or list(MODES):
                r = one_run(case, mode)
                print(json.dumps(r), flush=True)
                results.append(r)
    text = table(results)
    print(text)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    if args.append:
        load = os.getloadavg()
        loads = [r["load"] for r in results if "load" in r]
        section = (
            "## Map latency beside the control loop (benchmarks/map_latency.py)\n\n"
            f"CAT on `cat_pushed_obstacle` variants with the five cameras; "
            f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
            + (
                f"load average {min(loads):.1f}-{max(loads):.1f} at the end of the runs"
                if loads
                else args.note or f"load average {load[0]:.1f} when tabulated"
            )
            + " (the machine is shared with other work). "
            "Capture to use: from the frame's submission (right after its "
            "capture) to the control loop's first contact query against a "
            "snapshot holding it.\n\n" + text + "\n" + READING
        )
        put_section(args.append, section)


if __name__ == "__main__":
    main()
