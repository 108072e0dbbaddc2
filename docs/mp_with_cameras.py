# SPDX-License-Identifier: Apache-2.0
"""MP (or another method) on the eight CAT paper scenes, declared objects and cameras.

Virtual clock; one JSON line per run: reached, final error, peak force, how
many periods found no collision-free IK solution. Usage:
``python docs/mp_with_cameras.py mp [scene,scene,...]``.
"""

import json
import sys
import time

from make_cat_scenes import SCENES

from cbp.executors import load_executor
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario

SC = SCENES
method = sys.argv[1]
scenes = sys.argv[2].split(",") if len(sys.argv) > 2 else SC
for scene in scenes:
    for source in ("ground_truth", "depth_camera"):
        t0 = time.time()
        s = load_scenario(
            f"scenarios/cat_{scene}.yaml",
            overrides={
                "perception.source": source,
                "method.name": method,
                "method.mp.timing.clock": "virtual",
                "method.cat.timing.clock": "virtual",
                "method.ik.timing.clock": "virtual",
            },
        )
        tr = load_executor(method)(s, False)
        m = run_metrics(tr, s.robot)
        ik = sum("no collision-free IK" in e for _, e in tr.events)
        print(
            json.dumps(
                {
                    "scene": scene,
                    "source": source,
                    "reached": m["reached"],
                    "final_mm": round(1e3 * (m["final_position_error_m"] or 0), 1),
                    "force": m["peak_contact_force_n"],
                    "noik": ik,
                    "wall_s": round(time.time() - t0, 1),
                }
            ),
            flush=True,
        )
