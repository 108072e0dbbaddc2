# SPDX-License-Identifier: Apache-2.0
"""One run of a sweep, as a worker executes it: outputs written atomically.

:func:`execute_run` is what a Ray task (or a pool process) calls. It writes the
run's outputs (those of ``cbp run``, plus ``result.json``) into a private
folder and renames it to ``DIR/runs/<run id>`` when complete, so a folder under
that name is always a finished run, never half of one. While the run is in
flight, ``DIR/runs/.running/<run id>.pid`` names the process doing it (to see
what is running, or to stop one) and ``<run id>.attempts`` counts the tries.

A run that raises is recorded (``status: error``, the exception and its
traceback) like a finished one; a worker that dies leaves no folder, and the
driver retries it or records it as failed.
"""

from __future__ import annotations

import json
import os
import shutil
import time
import traceback
import uuid
from pathlib import Path
from typing import Any

__all__ = ["RESULT", "execute_run", "read_result", "write_result"]

#: The file in each run folder that says how it ended.
RESULT = "result.json"


def execute_run(run: dict[str, Any], out: str) -> dict[str, Any]:
    """Run one sweep run and write its folder; return its result record.

    Args:
        run: the :class:`~cbp.sweep.spec.RunSpec` as a dict.
        out: the sweep's output folder.
    """
    runs = Path(out) / "runs"
    running = runs / ".running"
    running.mkdir(parents=True, exist_ok=True)
    run_id = run["id"]
    attempts_file = running / f"{run_id}.attempts"
    attempts = int(attempts_file.read_text()) + 1 if attempts_file.exists() else 1
    attempts_file.write_text(str(attempts))
    (running / f"{run_id}.pid").write_text(str(os.getpid()))
    staging = runs / f".tmp-{run_id}-{uuid.uuid4().hex[:8]}"
    staging.mkdir(parents=True)
    start = time.perf_counter()
    record: dict[str, Any] = {
        "id": run_id,
        "scenario_file": run["scenario"],
        "method": run["method"],
        "seed": run["seed"],
        "values": run["values"],
        "attempts": attempts,
        "worker_pid": os.getpid(),
        "host": os.uname().nodename,
    }
    try:
        record |= _run(run, staging)
        record["status"] = "ok"
    except Exception as exc:  # recorded, never lost: the sweep goes on
        record["status"] = "error"
        record["error"] = f"{type(exc).__name__}: {exc}"
        record["traceback"] = traceback.format_exc()
    record["wall_s"] = time.perf_counter() - start
    write_result(staging, record)
    target = runs / run_id
    try:
        os.replace(staging, target)  # atomic: the folder appears complete
    except OSError:  # another attempt finished first: keep its folder
        shutil.rmtree(staging, ignore_errors=True)
    for name in (f"{run_id}.pid", f"{run_id}.attempts"):
        (running / name).unlink(missing_ok=True)
    return record


def _run(run: dict[str, Any], folder: Path) -> dict[str, Any]:
    """Load, run and write outputs into ``folder``; the record's run fields."""
    from cbp.executors import load_executor
    from cbp.report import write_outputs
    from cbp.scenario import load_scenario

    scenario = load_scenario(run["scenario"], overrides=run["overrides"])
    method = run["method"]
    executor = load_executor(method)
    trace = executor(scenario, False)
    metrics = write_outputs(scenario, {method: trace}, folder)[method]
    return {
        "scenario": scenario.spec.name,
        "sim_s": float(trace.t[-1]) if trace.t.size else 0.0,
        "metrics": metrics,
    }


def write_result(folder: Path, record: dict[str, Any]) -> None:
    """Write ``result.json`` through a temporary file (never a partial file)."""
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / f".{RESULT}.{os.getpid()}"
    tmp.write_text(json.dumps(record, indent=2, default=str) + "\n")
    os.replace(tmp, folder / RESULT)


def read_result(folder: Path) -> dict[str, Any] | None:
    """The run's record, or None if the folder has none (or an unreadable one)."""
    try:
        data = json.loads((folder / RESULT).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None
