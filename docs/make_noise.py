"""The CAT paper's scenes with cameras, noise on and off: docs/noise.md's table.

Run: PYTHONPATH=. .venv/bin/python docs/make_noise.py [--scenes boards ...]

Each scene runs once per setting with ``perception.source: depth_camera`` and
the virtual clock (``method.cat.timing.clock: virtual``: every frame is mapped
as it is captured and each period's planning budget is counted in steps, so a
run is reproducible and does not depend on the machine's load). "off" sets
``noise.enabled: false`` on every camera: frames as rendered, as before the
model existed; "on" the defaults; "on, edges" with the far side of depth
edges lost too (``edge_jump: 0.03``). Besides the run's metrics
(``cbp/metrics.py``) it reports what the map did: the free cells made unknown
by the hidden-space rule (a reading more than two cells nearer than the range
seen free before; in these static scenes every such cell is a false alarm)
and the readings dropped as the robot's own.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from make_cat_scenes import SCENES

from cbp.executors import make_planner
from cbp.metrics import run_metrics
from cbp.run import build_run
from cbp.run.loop import run_loop
from cbp.scenario import load_scenario

ROOT = Path(__file__).parents[1]
#: The settings compared, each fields set on every camera's noise model.
SETTINGS: dict[str, dict[str, str]] = {
    "off": {"enabled": "false"},
    "on": {},
    "on, edges": {"edge_jump": "0.03"},
}
BASE = {
    "perception.source": "depth_camera",
    "method.cat.timing.clock": "virtual",
}


def run_scene(
    scene: str, noise: dict[str, str] | None = None
) -> dict[str, float | int | bool | None]:
    """One run of ``cat_<scene>``; ``noise``: fields set on every camera's model."""
    path = ROOT / "scenarios" / f"cat_{scene}.yaml"
    overrides = dict(BASE)
    cameras = load_scenario(path, overrides=BASE).spec.perception.all_cameras
    for key, value in (noise or {}).items():
        for camera in cameras:
            overrides[f"perception.cameras.{camera.name}.noise.{key}"] = value
    scenario = load_scenario(path, overrides=overrides)
    timing = scenario.spec.method.timing("cat")
    parts = build_run(scenario, method="cat", clock=timing.clock)
    try:
        planner = make_planner("cat", parts)
    except BaseException:
        parts.close()
        raise
    assert parts.cameras is not None
    grid = parts.cameras.grid
    start = time.perf_counter()
    trace = run_loop(parts, planner, timing)
    m = run_metrics(trace)
    return {
        "reached": bool(m["reached"]),
        "total": m["total_time_s"],
        "error": m["final_position_error_m"],
        "force": m["peak_contact_force_n"],
        "clearance": m["min_clearance_m"],
        "hidden": grid.hidden_cells,
        "frames": grid.frames,
        "robot": grid.robot_points_removed,
        "events": len(trace.events),
        "wall": time.perf_counter() - start,
    }


def cost(scene: str = "shelf_reach", repeats: int = 300) -> None:
    """Print the model's cost per frame of each camera of ``cat_<scene>``.

    Each camera renders its first frame without noise; the model is applied
    to it ``repeats`` times (median and fastest; the machine is shared, so
    the fastest is the cost without interference).
    """
    from dataclasses import replace

    from cbp.sim.camera import DepthCamera
    from cbp.sim.depth_noise import NoisyDepth
    from cbp.sim.scene import simulate
    from cbp.sim.simulation import Simulation
    from cbp.state import RobotState

    scenario = load_scenario(ROOT / "scenarios" / f"cat_{scene}.yaml", overrides=BASE)
    spec = scenario.spec
    sim = simulate(Simulation, scenario)
    state = RobotState(scenario.robot)
    state.update(sim.q.copy())
    print(
        "| camera | pixels | readings | lost (edges, dropout) | median ms "
        "| fastest ms | rendering, median ms |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    try:
        for c in spec.perception.all_cameras:
            exact = replace(c, noise=replace(c.noise, enabled=False))
            camera = DepthCamera(sim.client, exact, scenario.robot)
            frame = camera.capture(state if camera.mounted else None)
            model = NoisyDepth(c.noise, c.name)
            far_plane = frame.buffer_limits[1]
            renders = []
            for _ in range(20):
                start = time.perf_counter()
                camera.capture(state if camera.mounted else None)
                renders.append(time.perf_counter() - start)
            times = []
            for _ in range(repeats):
                start = time.perf_counter()
                noisy = model.apply(frame.depth, frame.near, frame.far, far_plane)
                times.append(time.perf_counter() - start)
            lost = np.mean(~replace(frame, depth=noisy).valid() & frame.valid())
            readings = np.mean(frame.valid() & (frame.depth < far_plane))
            print(
                f"| {c.name} | {c.width}x{c.height} | {readings:.0%} | {lost:.1%} | "
                f"{np.median(times) * 1e3:.2f} | {min(times) * 1e3:.2f} | "
                f"{np.median(renders) * 1e3:.1f} |"
            )
    finally:
        sim.close()


def _f(value: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if value is None else f"{value * scale:.{digits}f}"


def main() -> None:
    """Run each scene with each setting; print one row per run."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scenes", nargs="*", default=SCENES, choices=SCENES)
    parser.add_argument(
        "--settings", nargs="*", default=list(SETTINGS), choices=list(SETTINGS)
    )
    parser.add_argument(
        "--cost", action="store_true", help="only time the model on each camera"
    )
    args = parser.parse_args()
    if args.cost:
        cost()
        return
    print(
        "| scene | noise | reached | total s | final error cm | peak force N | "
        "min clearance mm | cells hidden | frames | robot readings dropped | "
        "events |"
    )
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for scene in args.scenes:
        for setting in args.settings:
            r = run_scene(scene, SETTINGS[setting])
            print(
                f"| {scene} | {setting} | "
                f"{'yes' if r['reached'] else 'no'} | {_f(r['total'])} | "
                f"{_f(r['error'], 100, 1)} | {r['force']:.0f} | "
                f"{_f(r['clearance'], 1000, 1)} | {r['hidden']} | {r['frames']} | "
                f"{r['robot']} | {r['events']} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
