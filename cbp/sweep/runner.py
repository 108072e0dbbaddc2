# SPDX-License-Identifier: Apache-2.0
"""Run a sweep on Ray (local or a cluster), or on a process pool without Ray.

:func:`run_sweep` expands the sweep file, skips the runs whose folder already
holds a result (a rerun resumes), runs the others as Ray tasks (or pool jobs),
and writes the results table and report (:mod:`cbp.sweep.results`).

* Without ``address``, Ray starts on this machine with ``workers`` CPUs; with
  one (``ray start --head`` printed it), the driver joins that cluster and each
  run takes one CPU wherever Ray places it. Every node needs ``cbp`` installed
  and the scenario files at the same path (a shared or identical checkout).
* A worker that dies (killed, out of memory, its node lost) is charged to the
  run it was running, and only to it: that run is retried (by Ray, or on a new
  pool process) up to ``retries`` times; then it is recorded as failed with the
  reason, in ``DIR/failed/<run id>.json``, and a later rerun tries it again. A
  run that raises is recorded with its exception and is not retried (it would
  raise again). ``cbp sweep`` exits with status 1 when any run is not ok
  (failed or raised), with either backend.
* A method that needs a process of its own to be reproducible
  (:attr:`cbp.executors.ExecutorInfo.fresh_process`: MP and the hybrid, which
  seed OMPL once per process) runs in a new worker process each time.
* Ctrl-C cancels the runs in flight; finished runs are kept and a rerun
  resumes.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from cbp.progress import Progress
from cbp.sweep.spec import RunSpec, expand, load_sweep
from cbp.sweep.worker import execute_run, read_result

__all__ = ["SweepOutcome", "run_sweep"]

#: Results that count as done: a rerun skips them.
DONE = ("ok", "error")


@dataclass
class SweepOutcome:
    """What a sweep invocation did.

    Attributes:
        out: the sweep's folder.
        runs: every run of the sweep.
        skipped: runs already done before this invocation.
        records: the result record of every run, done or failed, by id.
        backend: ``ray`` or ``process pool``.
        interrupted: stopped by Ctrl-C before every run was done.
        startup_s: time to start (or join) the backend [s].
    """

    out: Path
    runs: list[RunSpec]
    skipped: int = 0
    records: dict[str, dict[str, Any]] = field(default_factory=dict)
    backend: str = ""
    interrupted: bool = False
    startup_s: float = 0.0

    @property
    def failed(self) -> int:
        """Runs that did not finish (worker lost) or raised."""
        return sum(r["status"] != "ok" for r in self.records.values())


def run_sweep(
    path: str | Path,
    out: str | Path,
    *,
    workers: int | None = None,
    address: str | None = None,
    progress: bool = True,
    backend: str = "auto",
) -> SweepOutcome:
    """Run the sweep file at ``path`` into ``out``; see the module docstring.

    Args:
        path: the sweep file.
        out: its output folder (created).
        workers: CPUs for a local Ray instance or the pool (default: all).
        address: a Ray cluster to join (``ray start --head`` prints it).
        progress: show progress: a bar on a terminal (runs done, failed, time
            left), else a line per finished run on standard error.
        backend: ``ray``, ``pool`` or ``auto`` (Ray if installed).

    Raises:
        ScenarioError: the sweep file, or an override in it, has a problem.
    """
    from cbp.sweep.results import write_results

    path, out = Path(path), Path(out)
    spec = load_sweep(path)
    out.mkdir(parents=True, exist_ok=True)
    scenes: list[Path] = []
    if spec.scenes is not None:
        from cbp.scenes import write_scenes

        scenes = write_scenes(out / "scenes", spec.scenes.count, spec.scenes.seed)
    runs = expand(spec, path, scenes)
    (out / "sweep.json").write_text(
        json.dumps([asdict(r) for r in runs], indent=1, default=str) + "\n"
    )
    outcome = SweepOutcome(out, runs)
    pending = []
    for run in runs:
        record = read_result(out / "runs" / run.id)
        if record is not None and record.get("status") in DONE:
            outcome.records[run.id] = record
            outcome.skipped += 1
        else:
            pending.append(run)
    workers = workers or os.cpu_count() or 1
    if backend == "auto":
        backend = "ray" if _has_ray() or address else "pool"
    outcome.backend = "ray" if backend == "ray" else "process pool"
    with Progress(len(runs), "sweep", outcome.skipped, lines=progress) as bar:

        def done(run: RunSpec, record: dict[str, Any]) -> None:
            outcome.records[run.id] = record
            failed_file = out / "failed" / f"{run.id}.json"
            if record["status"] == "failed":
                failed_file.parent.mkdir(exist_ok=True)
                failed_file.write_text(json.dumps(record, indent=2) + "\n")
            else:
                failed_file.unlink(missing_ok=True)
            bar.advance(record.get("method", ""), record["status"] != "ok")

        try:
            if pending and backend == "ray":
                outcome.startup_s = _run_ray(
                    pending, out, workers, address, spec.retries, done
                )
            elif pending:
                outcome.startup_s = _run_pool(pending, out, workers, spec.retries, done)
        except KeyboardInterrupt:
            outcome.interrupted = True
    write_results(outcome, spec, path)
    return outcome


def _has_ray() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def _failed(run: RunSpec, reason: str, attempts: int) -> dict[str, Any]:
    """The record of a run whose worker died every time it was tried."""
    return {
        "id": run.id,
        "scenario_file": run.scenario,
        "method": run.method,
        "seed": run.seed,
        "values": run.values,
        "status": "failed",
        "error": reason,
        "attempts": attempts,
    }


def _run_ray(
    pending: list[RunSpec],
    out: Path,
    workers: int,
    address: str | None,
    retries: int,
    done: Callable[[RunSpec, dict[str, Any]], None],
) -> float:
    """Each run a Ray task; returns Ray's start-up time [s]."""
    import ray

    from cbp.methods import METHODS

    start = time.perf_counter()
    options: dict[str, Any] = {
        "logging_level": "ERROR",
        "log_to_driver": False,
        "configure_logging": True,
    }
    if address:
        ray.init(address=address, **options)
    else:
        ray.init(num_cpus=workers, include_dashboard=False, **options)
    startup = time.perf_counter() - start
    try:
        options = {"num_cpus": 1, "max_retries": retries, "retry_exceptions": False}
        task = ray.remote(**options)(execute_run)
        # OMPL seeds its samplers once per process: an MP or hybrid run gets a
        # fresh process so that it is reproducible (cbp.executors.mp).
        fresh = ray.remote(max_calls=1, **options)(execute_run)
        refs = {}
        for run in pending:
            remote = fresh if METHODS[run.method].fresh_process else task
            refs[remote.remote(asdict(run), str(out))] = run
        try:
            while refs:
                ready, _ = ray.wait(list(refs), num_returns=1, timeout=1.0)
                for ref in ready:
                    run = refs.pop(ref)
                    try:
                        record = ray.get(ref)
                    except ray.exceptions.RayError as exc:
                        reason = f"{type(exc).__name__}: {str(exc).splitlines()[0]}"
                        record = _failed(run, reason, retries + 1)
                    done(run, record)
        except KeyboardInterrupt:
            for ref in refs:
                ray.cancel(ref, force=True)
            raise
    finally:
        ray.shutdown()
    return startup


def _run_pool(
    pending: Iterable[RunSpec],
    out: Path,
    workers: int,
    retries: int,
    done: Callable[[RunSpec, dict[str, Any]], None],
) -> float:
    """Without Ray: worker processes, each running one run at a time.

    The driver knows which run each worker holds, so a worker that dies
    (killed, out of memory) is charged to that run alone: it is tried again up
    to ``retries`` times on a new worker, then recorded as failed, while the
    other workers carry on. A run whose method needs a fresh process
    (:attr:`~cbp.executors.ExecutorInfo.fresh_process`) gets a new worker that
    ends after it.

    Workers are spawned, not forked: a fork copies the parent's threads' locks
    in whatever state they were (Ray's, a map thread's, a web server's), and the
    child can die or hang on one before it runs anything.
    """
    import multiprocessing
    from collections import deque
    from multiprocessing.connection import wait

    from cbp.methods import METHODS

    context = multiprocessing.get_context("spawn")
    queue = deque(pending)
    tries = {run.id: 0 for run in queue}
    idle: list[_Worker] = []
    busy: list[_Worker] = []
    try:
        while queue or busy:
            while queue and len(busy) < workers:
                run = queue.popleft()
                fresh = METHODS[run.method].fresh_process
                if fresh or not idle:
                    if idle and len(idle) + len(busy) >= workers:
                        idle.pop().stop()  # at most `workers` processes
                    worker = _Worker(context)
                else:
                    worker = idle.pop()
                worker.start_run(run, out, last=fresh)
                busy.append(worker)
            wait([w.connection for w in busy] + [w.process.sentinel for w in busy])
            for worker in list(busy):
                held = worker.run
                assert held is not None
                run = held
                record = worker.result()
                if record is None and worker.process.is_alive():
                    continue  # still running
                busy.remove(worker)
                if record is not None:
                    done(run, record)
                    if METHODS[run.method].fresh_process:
                        worker.stop()
                    else:
                        idle.append(worker)
                    continue
                worker.stop()
                tries[run.id] += 1
                if tries[run.id] > retries:
                    code = worker.process.exitcode
                    reason = f"worker process died (exit code {code})"
                    done(run, _failed(run, reason, tries[run.id]))
                else:
                    queue.append(run)
    finally:
        for worker in idle + busy:
            worker.stop(kill=worker in busy)
    return 0.0


class _Worker:
    """A spawned process that runs the sweep runs it is sent, one at a time."""

    def __init__(self, context: Any) -> None:
        self.connection, child = context.Pipe()
        self.process = context.Process(target=_serve, args=(child,), daemon=True)
        self.process.start()
        child.close()
        self.run: RunSpec | None = None

    def start_run(self, run: RunSpec, out: Path, last: bool) -> None:
        """Send ``run``; with ``last`` the process ends after it."""
        self.run = run
        self.connection.send((asdict(run), str(out), last))

    def result(self) -> dict[str, Any] | None:
        """The run's record if it has come, else None (running, or died)."""
        try:
            if self.connection.poll():
                record: dict[str, Any] = self.connection.recv()
                return record
        except (EOFError, OSError):  # died while sending
            pass
        return None

    def stop(self, kill: bool = False) -> None:
        """End the process: ask it to (idle), or kill it (running a run)."""
        if self.process.is_alive() and not kill:
            try:
                self.connection.send(None)
            except OSError:
                kill = True
            self.process.join(timeout=10)
        if self.process.is_alive():
            self.process.kill()
        self.process.join()
        self.connection.close()


def _serve(connection: Any) -> None:
    """A pool worker's loop: run each run received, send back its record."""
    while True:
        try:
            job = connection.recv()
        except (EOFError, KeyboardInterrupt):
            return
        if job is None:
            return
        run, out, last = job
        connection.send(execute_run(run, out))
        if last:
            return
