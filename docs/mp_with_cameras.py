# SPDX-License-Identifier: Apache-2.0
"""MP (or another method) on the eight CAT paper scenes, declared objects and cameras.

Virtual clock; one JSON line per run: reached, final error, peak force, how
many periods found no collision-free IK solution, looks at an unseen goal and
plans. Each run is a process of its own: OMPL seeds its random numbers once
per process, so only a process's first plan is reproducible. Usage:
``python docs/mp_with_cameras.py mp [scene,scene,...] [ground_truth|depth_camera]``.
"""

import json
import subprocess
import sys
import time
from pathlib import Path

from make_cat_scenes import SCENES

from cbp.executors import load_executor
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario

SOURCES = ("ground_truth", "depth_camera")


def one(method: str, scene: str, source: str) -> dict[str, object]:
    """One run on the virtual clock, as a JSON-ready record."""
    t0 = time.time()
    s = load_scenario(
        Path(__file__).parents[1] / f"scenarios/cat_{scene}.yaml",
        overrides={
            "perception.source": source,
            "method.name": method,
            **{f"method.{m}.timing.clock": "virtual" for m in ("mp", "cat", "ik")},
        },
    )
    tr = load_executor(method)(s, False)
    m = run_metrics(tr, s.robot)
    return {
        "scene": scene,
        "source": source,
        "method": method,
        "reached": m["reached"],
        "final_mm": round(1e3 * (m["final_position_error_m"] or 0), 1),
        "force": m["peak_contact_force_n"],
        "noik": sum("no collision-free IK" in e for _, e in tr.events),
        "looks": m.get("looks", 0),
        "plans": m.get("plans", 0),
        "wall_s": round(time.time() - t0, 1),
    }


if __name__ == "__main__":
    method = sys.argv[1]
    if len(sys.argv) == 5 and sys.argv[4] == "--one":
        print(json.dumps(one(method, sys.argv[2], sys.argv[3])), flush=True)
        sys.exit(0)
    scenes = sys.argv[2].split(",") if len(sys.argv) > 2 else SCENES
    sources = sys.argv[3].split(",") if len(sys.argv) > 3 else SOURCES
    for scene in scenes:
        for source in sources:
            subprocess.run(
                [sys.executable, __file__, method, scene, source, "--one"], check=True
            )
