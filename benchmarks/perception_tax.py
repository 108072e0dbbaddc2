"""The perception tax: each scene run with the declared objects and with the cameras.

Every run is on the virtual clock (the same outcome on any machine and under
any load) and in a process of its own (OMPL seeds its samplers once per
process). Per scene and method the table gives, for each obstacle source:
reached or not, the final distance to the goal, the peak contact force and
the time to reach; and, for each camera run that stops short where the
declared run reached, why, read from the run's events and command periods:

* ``goal unseen``: the goal lay in an obstacle or in space no camera had
  seen when the run ended (the goal-check event, not followed by "open
  space again");
* ``unseen space``: the arm was held by space no camera had seen (CAT's
  event), or a planner's IK search found no collision-free configuration
  while unseen space counted as an obstacle;
* ``moving obstacle``: an obstacle the cameras saw moving was nearer than
  the arm needs to get away (its cells grown by the look-ahead);
* ``bad frames``: frames dropped, a camera without valid frames for its
  timeout, or the map behind the cameras (the robot stopped);
* ``no plan``: the planner found no plan (no IK solution, no RRT-Connect path
  in its budget) without unseen space being named;
* ``noise``: with ``--noise-check SOURCES``, the run reaches when it is made again
  with the cameras' noise down to 0.1 mm and no dropout (:data:`QUIET`),
  and none of the reasons above was given (the table says in any case
  whether that run reaches);
* otherwise the reason :func:`cbp.story.run_sentence` gives (the last
  periods' notes, or the last event).

Scene sets: ``cat`` (the CAT paper's eight scenes), ``mbm``
(MotionBenchMaker's Panda families, ``cbp.mbm``; ``--mbm DIR``, a
MotionBenchMaker checkout), ``clutter`` and ``moving`` (``cbp.scenes``).
MotionBenchMaker problems have two camera variants: ``cameras`` (ours, five
cameras turned to the goal) and ``mbm_cameras`` (the placements of
MotionBenchMaker's sensor files).

Run: PYTHONPATH=. .venv/bin/python -m benchmarks.perception_tax --sets mbm
     --mbm PATH --per-family 3 --methods cat,hybrid,mp,ik
     [--out out/perception_tax] [--from-log out/perception_tax/runs.jsonl]
Prints a markdown table and the tax (reach rate with cameras / with the
declared objects) per camera variant; the runs are appended to
``OUT/runs.jsonl`` and a rerun skips those already there.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: The CAT paper's eight scenes (docs/cat_scenes.md), in its order.
CAT_SCENES = (
    "free_step",
    "free_continuous",
    "boards",
    "local_minimum",
    "wrist_limit",
    "unreachable",
    "shelf_reach",
    "shelf_retreat",
)
METHODS = ("cat", "hybrid", "mp", "ik")
#: Obstacle sources: the declared objects, our cameras, MotionBenchMaker's.
SOURCES = ("declared", "cameras", "mbm_cameras")
#: The methods whose timing sections select the clock (the hybrid runs CAT's).
CLOCKED = ("cat", "ik", "mp")

#: "Noise off": 0.1 mm of depth noise and no dropout. Not none: a frame
#: exactly like the last one while the arm moved in the camera's view is
#: refused as frozen (cbp.perception.plausibility), and a fixed camera whose
#: view of the arm is hidden behind an obstacle gives exactly that.
QUIET = {"sigma_0": "0.0001", "sigma_growth": "0.0", "dropout": "0.0"}

GOAL_UNSEEN = "goal lies in an obstacle or in space no camera has seen"
GOAL_OPEN = "goal is in open space again"


def reason(events: list[str], notes: list[str]) -> str:
    """Why a camera run stopped short, from its events and last periods' notes."""
    found = []
    goal_unseen = False
    for e in events:
        if e.startswith(GOAL_UNSEEN):
            goal_unseen = True
        elif e.startswith(GOAL_OPEN):
            goal_unseen = False
    if goal_unseen:
        found.append("goal unseen")
    if any(e.startswith("held by space no camera has seen") for e in events) or any(
        "no collision-free IK" in e and "no camera has seen" in e for e in events
    ):
        found.append("unseen space")
    if any("the cameras see moving" in e for e in events):
        found.append("moving obstacle")
    if any(
        "frame dropped" in e or "robot stopped" in e or "behind the cameras" in e
        for e in events
    ):
        found.append("bad frames")
    planner = (
        "no collision-free IK",
        "no plan in time",
        "no collision-free configuration",
        "within the planner's padding",
    )
    if (
        any(any(p in e for p in planner) for e in events)
        or any("no plan" in n for n in notes)
    ) and "unseen space" not in found:
        found.append("no plan")
    return ", ".join(found)


def one(path: Path, method: str, source: str, noise: bool = True) -> dict[str, Any]:
    """One run on the virtual clock, as a JSON-ready record."""
    from cbp.executors import load_executor
    from cbp.metrics import run_metrics
    from cbp.scenario import load_scenario
    from cbp.story import run_sentence

    t0 = time.perf_counter()
    overrides = {
        "perception.source": "ground_truth" if source == "declared" else "depth_camera",
        "method.name": method,
        **{f"method.{m}.timing.clock": "virtual" for m in CLOCKED},
    }
    if not noise:
        scenario = load_scenario(path)
        for k in range(len(scenario.spec.perception.all_cameras)):
            for key, value in QUIET.items():
                overrides[f"perception.cameras.{k}.noise.{key}"] = value
    scenario = load_scenario(path, overrides=overrides)
    trace = load_executor(method)(scenario, False)
    m = run_metrics(trace, scenario.robot)
    events = [e for _, e in trace.events]
    notes = [p.note for p in trace.periods[-30:] if not p.spliced and p.note]
    error = m.get("final_position_error_m")
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return {
        "scene": scenario.spec.name,
        "method": method,
        "source": source,
        "noise": noise,
        "reached": bool(m["reached"]),
        "final_mm": None if error is None else round(1e3 * error, 1),
        "peak_n": round(float(m.get("peak_contact_force_n") or 0.0), 1),
        "time_s": m.get("total_time_s"),
        "duration_s": scenario.spec.duration,
        "reason": "" if m["reached"] or source == "declared" else reason(events, notes),
        "story": run_sentence(method, trace, m),
        "events": events[:40],
        "wall_s": round(time.perf_counter() - t0, 1),
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 1),
    }


def scenes(args: argparse.Namespace) -> list[tuple[str, Path, Path | None]]:
    """(set, scenario file, MotionBenchMaker-cameras twin or None) per scene."""
    out: list[tuple[str, Path, Path | None]] = []
    for name in args.sets.split(","):
        if name == "cat":
            out += [
                ("cat", ROOT / "scenarios" / f"cat_{s}.yaml", None) for s in CAT_SCENES
            ]
        elif name == "mbm":
            from cbp.mbm import write_problems

            if args.mbm is None:
                sys.exit("--sets mbm needs --mbm DIR (a MotionBenchMaker checkout)")
            folder = args.out / "scenes" / "mbm"
            families = args.families.split(",") if args.families else None
            paths = write_problems(
                args.mbm, folder, args.per_family, args.seed, families
            )
            for path in paths:
                twin = path.with_name(f"{path.stem}_mbm_cameras.yaml")
                out.append(("mbm", path, twin))
        elif name in ("clutter", "moving"):
            from cbp.scenes import write_scenes

            folder = args.out / "scenes" / name
            paths = write_scenes(folder, args.count, args.seed, name == "moving")
            out += [(name, p, None) for p in paths]
        else:
            sys.exit(f"unknown scene set {name!r}: choose cat, mbm, clutter, moving")
    return out


def run_all(args: argparse.Namespace, log: Path) -> None:
    """Run what the log does not hold yet, one process after the other.

    With ``--noise-check SOURCES`` (``cameras``, ``mbm_cameras``), a run of
    those that stops short where the declared run reached is made again with
    the cameras' noise at 0.1 mm (:data:`QUIET`).
    """
    records = read(log)
    done = {(r["scene"], r["method"], r["source"], r["noise"]): r for r in records}
    methods = args.methods.split(",")
    sources = args.sources.split(",")
    mbm_methods = args.mbm_cameras_for.split(",") if args.mbm_cameras_for else methods
    checked = args.noise_check.split(",") if args.noise_check else []
    for _, path, twin in scenes(args):
        for method in methods:
            for source in sources:
                file = twin if source == "mbm_cameras" else path
                if file is None or (
                    source == "mbm_cameras" and method not in mbm_methods
                ):
                    continue
                key = (path.stem, method, source, True)
                if key not in done:
                    done[key] = spawn(file, method, source, True, args.timeout)
                    done[key]["scene"] = path.stem  # the twin's runs count too
                    append(log, done[key])
                declared = done.get((path.stem, method, "declared", True))
                tax = declared is not None and declared["reached"]
                quiet = (path.stem, method, source, False)
                if (
                    source in checked
                    and tax
                    and not done[key]["reached"]
                    and quiet not in done
                ):
                    done[quiet] = spawn(file, method, source, False, args.timeout)
                    done[quiet]["scene"] = path.stem
                    append(log, done[quiet])


def spawn(
    path: Path, method: str, source: str, noise: bool, timeout: float
) -> dict[str, Any]:
    """:func:`one` in a process of its own; a run over ``timeout`` [s] is recorded."""
    command = [sys.executable, __file__, "--one", str(path), method, source]
    if not noise:
        command.append("--noise-off")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.perf_counter()
    try:
        done = subprocess.run(
            command, capture_output=True, text=True, timeout=timeout, env=env
        )
    except subprocess.TimeoutExpired:
        return failed(path, method, source, noise, f"over {timeout:g} s of wall time")
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or ["no output"]
        return failed(path, method, source, noise, f"raised: {tail[0]}")
    record: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    record["wall_s"] = round(time.perf_counter() - t0, 1)
    return record


def failed(
    path: Path, method: str, source: str, noise: bool, why: str
) -> dict[str, Any]:
    """The record of a run that gave no result."""
    return {
        "scene": path.stem,
        "method": method,
        "source": source,
        "noise": noise,
        "reached": False,
        "final_mm": None,
        "peak_n": None,
        "time_s": None,
        "reason": f"no result: {why}",
        "events": [],
    }


def read(log: Path) -> list[dict[str, Any]]:
    """The records of ``log`` (none when it does not exist)."""
    if not log.is_file():
        return []
    return [json.loads(line) for line in log.read_text().splitlines() if line]


def append(log: Path, record: dict[str, Any]) -> None:
    """Add ``record`` to ``log`` and say it on standard error."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("a") as f:
        f.write(json.dumps(record) + "\n")
    print(
        f"{record['scene']} {record['method']} {record['source']}"
        f"{'' if record['noise'] else ' (0.1 mm noise)'}: "
        f"{'reached' if record['reached'] else 'not reached'} "
        f"{record.get('wall_s', '-')} s {record['reason']}",
        file=sys.stderr,
        flush=True,
    )


def _cell(r: dict[str, Any] | None) -> str:
    if r is None:
        return "-"
    if r["final_mm"] is None:
        return "no result"
    force = f"{r['peak_n']:.0f} N"
    if r["reached"]:
        return f"yes; {r['time_s']:.1f} s; {force}"
    return f"no; {r['final_mm']:.0f} mm; {force}"


def table(records: Iterable[dict[str, Any]]) -> str:
    """The markdown table, per-source reach counts, and the tax per camera variant."""
    runs: dict[tuple[str, str], dict[str, dict[str, Any]]] = {}
    rechecked: dict[tuple[str, str, str], bool] = {}
    for r in records:
        if r["noise"]:
            runs.setdefault((r["scene"], r["method"]), {})[r["source"]] = r
        else:
            rechecked[(r["scene"], r["method"], r["source"])] = r["reached"]
    sources = [s for s in SOURCES if any(s in v for v in runs.values())]
    lines = [
        "| scene | method | "
        + " | ".join(f"{s}: reached; time or final error; peak" for s in sources)
        + " | why the cameras stop short |",
        "|---|---|" + "---|" * len(sources) + "---|",
    ]
    for (scene, method), by in sorted(runs.items()):
        why = []
        for s in sources[1:]:
            r = by.get(s)
            if r is None or r["reached"]:
                continue
            text = r["reason"]
            quiet = rechecked.get((scene, method, s))
            if quiet is not None:
                said = "noise" if quiet and not text else ""
                said = said or ("reaches" if quiet else "stops short") + " at 0.1 mm"
                text = f"{text}; {said}" if text else said
            declared = by.get("declared")
            if declared is not None and not declared["reached"]:
                text = f"declared stops too{'; ' + text if text else ''}"
            if not text:
                story = r.get("story", "")
                text = story.split(", ", 1)[-1].rstrip(".") if story else "not said"
            why.append(f"{s}: {text}")
        cells = " | ".join(_cell(by.get(s)) for s in sources)
        lines.append(f"| {scene} | {method} | {cells} | {'; '.join(why)} |")
    lines.append("")
    counts = {}
    for s in sources:
        rs = [by[s] for by in runs.values() if s in by]
        counts[s] = (sum(r["reached"] for r in rs), len(rs))
        lines.append(f"- {s}: reached {counts[s][0]} of {counts[s][1]}")
    methods = sorted({method for _, method in runs})
    for m in methods:
        counts_m = []
        for s in sources:
            rs = [by[s] for (_, mm), by in runs.items() if mm == m and s in by]
            if rs:
                counts_m.append(f"{s} {sum(r['reached'] for r in rs)} of {len(rs)}")
        lines.append(f"- {m}: reached " + ", ".join(counts_m))
    for s in sources[1:]:
        both = [by for by in runs.values() if s in by and "declared" in by]
        a = sum(by[s]["reached"] for by in both)
        b = sum(by["declared"]["reached"] for by in both)
        rate = f"{a / b:.2f}" if b else "undefined"
        lines.append(
            f"\n**Tax ({s}): reached {a} of {len(both)} with cameras / {b} of "
            f"{len(both)} with declared objects = {rate}**"
        )
    return "\n".join(lines)


def main() -> None:
    """Run (or read) the runs, print the table."""
    if len(sys.argv) > 1 and sys.argv[1] == "--one":
        path, method, source = sys.argv[2:5]
        noise = "--noise-off" not in sys.argv
        print(json.dumps(one(Path(path), method, source, noise)), flush=True)
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sets", default="cat,mbm", help="cat, mbm, clutter, moving")
    parser.add_argument("--mbm", type=Path, help="a MotionBenchMaker checkout")
    parser.add_argument("--per-family", type=int, default=3)
    parser.add_argument("--families", help="MotionBenchMaker families (default: all)")
    parser.add_argument("--count", type=int, default=10, help="clutter/moving scenes")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--sources", default=",".join(SOURCES))
    parser.add_argument("--timeout", type=float, default=900.0, help="per run [s]")
    parser.add_argument(
        "--mbm-cameras-for", help="methods run with MotionBenchMaker's cameras too"
    )
    parser.add_argument(
        "--noise-check",
        help="camera sources whose runs that stop short are made again at 0.1 mm",
    )
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "perception_tax")
    parser.add_argument("--from-log", type=Path, help="tabulate these runs only")
    args = parser.parse_args()
    log = args.from_log or args.out / "runs.jsonl"
    if args.from_log is None:
        run_all(args, log)
    print(table(read(log)))


if __name__ == "__main__":
    main()
