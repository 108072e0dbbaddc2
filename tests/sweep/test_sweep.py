"""cbp sweep: strict sweep files, stable run ids, Ray and pool backends, resuming."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from cbp.errors import ScenarioError
from cbp.sweep import load_sweep, run_sweep
from cbp.sweep.spec import expand
from cbp.sweep.worker import execute_run, read_result

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
REACH = SCENARIOS / "panda_reach.yaml"


def _sweep(tmp_path: Path, body: str, name: str = "sweep.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(body).format(reach=REACH))
    return path


EIGHT = """\
    name: eight
    scenarios: ["{reach}"]
    methods: [kinematic]
    set: {{duration: 1.0}}
    grid:
      method.kinematic.dt: [0.01, 0.02]
      solver.name: [daqp, piqp]
    samples:
      count: 2
      seed: 7
      values:
        collision.activation_distance: {{uniform: [0.05, 0.1]}}
    """


def test_a_bad_sweep_file_lists_every_problem_located(tmp_path: Path) -> None:
    path = _sweep(
        tmp_path,
        """\
        name: bad
        scenarios: ["{reach}"]
        methods: [cat, catt]
        grid:
          duration: []
        samples:
          count: 2
          values:
            duration: {{normal: [0, 1]}}
        retrys: 3
        """,
    )
    with pytest.raises(ScenarioError) as info:
        load_sweep(path)
    text = str(info.value)
    assert "line 10" in text
    assert "retrys" in text
    assert "'retries'" in text
    path.write_text(path.read_text().replace("retrys: 3\n", ""))
    with pytest.raises(ScenarioError) as info:
        load_sweep(path)
    text = str(info.value)
    assert "methods[1]: unknown method 'catt'" in text
    assert "grid.duration: give at least one value" in text
    assert "samples.values.duration: expected one of {uniform, log_uniform" in text


def test_run_ids_are_stable_and_follow_the_scenario_after_overrides(
    tmp_path: Path,
) -> None:
    path = _sweep(tmp_path, EIGHT)
    spec = load_sweep(path)
    runs = expand(spec, path, [])
    assert len(runs) == 8
    assert len({r.id for r in runs}) == 8
    assert [r.id for r in expand(spec, path, [])] == [r.id for r in runs]
    # The same values reached in another sweep, in another order, give the
    # same run.
    distance = runs[0].values["collision.activation_distance"]
    other = _sweep(
        tmp_path,
        f"""\
        name: other
        scenarios: ["{{reach}}"]
        methods: [kinematic]
        set: {{{{duration: 1.0, solver.name: daqp}}}}
        grid:
          collision.activation_distance: [{distance!r}]
          method.kinematic.dt: [0.01]
        """,
        "other.yaml",
    )
    (same,) = expand(load_sweep(other), other, [])
    assert same.id == runs[0].id
    assert runs[0].values["solver.name"] == "daqp"
    # An override the scenario does not have is a located error.
    bad = _sweep(
        tmp_path,
        """\
        name: bad
        scenarios: ["{reach}"]
        methods: [kinematic]
        set: {{method.kinematic.dtt: 0.01}}
        """,
        "bad.yaml",
    )
    with pytest.raises(ScenarioError, match="dtt"):
        expand(load_sweep(bad), bad, [])


def test_eight_runs_on_local_ray_then_a_rerun_runs_nothing(tmp_path: Path) -> None:
    path = _sweep(tmp_path, EIGHT)
    out = tmp_path / "out"
    first = run_sweep(path, out, workers=2, progress=False, backend="ray")
    assert first.backend == "ray"
    assert first.skipped == 0
    assert first.failed == 0
    lines = (out / "results.csv").read_text().splitlines()
    assert len(lines) == 1 + 8
    import pyarrow.parquet as pq

    table = pq.read_table(out / "results.parquet")
    assert table.num_rows == 8
    assert set(table.column("status").to_pylist()) == {"ok"}
    assert (
        sorted(table.column("set.solver.name").to_pylist())
        == ["daqp"] * 4 + ["piqp"] * 4
    )
    for run in first.runs:
        folder = out / "runs" / run.id
        assert {"result.json", "metrics.json", "trace.csv", "report.md"} <= {
            p.name for p in folder.iterdir()
        }
    assert not [p for p in (out / "runs").iterdir() if p.name.startswith(".tmp")]
    report = (out / "report.md").read_text()
    assert "| kinematic | 8 | 8 | 0 | 0 |" in report
    second = run_sweep(path, out, workers=2, progress=False, backend="ray")
    assert second.skipped == 8
    assert second.startup_s == 0.0  # Ray was not even started
    assert len(second.records) == 8


def test_the_pool_backend_and_a_run_that_raises(tmp_path: Path) -> None:
    path = _sweep(
        tmp_path,
        """\
        name: pool
        scenarios: ["{reach}"]
        methods: [kinematic]
        set: {{duration: 0.5}}
        grid:
          method.kinematic.dt: [0.01, 0.05]
        """,
    )
    outcome = run_sweep(
        path, tmp_path / "out", workers=2, progress=False, backend="pool"
    )
    assert outcome.backend == "process pool"
    statuses = [r["status"] for r in outcome.records.values()]
    assert statuses == ["ok", "ok"], [r.get("error") for r in outcome.records.values()]
    # A run whose scenario cannot be loaded raises in the worker: recorded.
    record = execute_run(
        {
            "id": "broken",
            "scenario": str(tmp_path / "missing.yaml"),
            "method": "kinematic",
            "seed": 0,
            "overrides": {},
            "values": {},
        },
        str(tmp_path / "out"),
    )
    assert record["status"] == "error"
    assert "missing.yaml" in record["error"]
    assert read_result(tmp_path / "out" / "runs" / "broken") == json.loads(
        json.dumps(record, default=str)
    )


def _sweep_process(path: Path, out: Path, backend: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "cbp",
            "sweep",
            str(path),
            "--out",
            str(out),
            "--workers",
            "2",
            "--backend",
            backend,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _kill_when_running(out: Path, run_id: str, sweep: subprocess.Popen[str]) -> None:
    """SIGKILL the worker of ``run_id`` as soon as its pid file appears."""
    pid_file = out / "runs" / ".running" / f"{run_id}.pid"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and sweep.poll() is None:
        try:
            pid = int(pid_file.read_text())
        except (OSError, ValueError):
            time.sleep(0.05)
            continue
        os.kill(pid, signal.SIGKILL)
        return
    raise AssertionError(f"run {run_id} never started")


@pytest.mark.slow
def test_a_killed_worker_is_retried_and_its_run_completes(tmp_path: Path) -> None:
    """Ray retries a run whose worker was killed; the sweep then exits 0."""
    path = _sweep(
        tmp_path,
        """\
        name: killed
        scenarios: ["{reach}"]
        methods: [kinematic]
        set: {{duration: 40.0}}
        grid:
          method.kinematic.dt: [0.005, 0.006]
        retries: 2
        """,
    )
    out = tmp_path / "out"
    killed = expand(load_sweep(path), path, [])[0].id
    sweep = _sweep_process(path, out, "ray")
    _kill_when_running(out, killed, sweep)
    stdout, stderr = sweep.communicate(timeout=300)
    assert sweep.returncode == 0, stderr
    record = read_result(out / "runs" / killed)
    assert record is not None
    assert record["status"] == "ok"
    assert record["attempts"] == 2
    assert "0 not ok" in stdout


KILLED = """\
    name: killed
    scenarios: ["{reach}"]
    methods: [kinematic]
    grid:
      duration: [{duration}, 0.5]
      tasks.hand.params.frame: [panda_hand, no_such_frame]
    retries: 0
    """


@pytest.mark.parametrize(
    "backend", ["pool", pytest.param("ray", marks=pytest.mark.slow)]
)
def test_a_dead_worker_is_charged_to_its_run_only(tmp_path: Path, backend: str) -> None:
    """Killing one run's worker fails that run alone; the sweep exits 1."""
    path = tmp_path / "sweep.yaml"
    path.write_text(textwrap.dedent(KILLED).format(reach=REACH, duration=60.0))
    runs = expand(load_sweep(path), path, [])
    (long,) = [
        r
        for r in runs
        if r.values == {"duration": 60.0, "tasks.hand.params.frame": "panda_hand"}
    ]
    out = tmp_path / "out"
    sweep = _sweep_process(path, out, backend)
    _kill_when_running(out, long.id, sweep)
    stdout, stderr = sweep.communicate(timeout=300)
    assert sweep.returncode == 1, stderr
    assert "3 not ok" in stdout
    records = {r.id: read_result(out / "runs" / r.id) for r in runs}
    assert records.pop(long.id) is None  # no folder: its worker died
    failed = json.loads((out / "failed" / f"{long.id}.json").read_text())
    assert "died" in failed["error"] or "Worker" in failed["error"]
    statuses = sorted(
        (r["values"]["tasks.hand.params.frame"], r["status"])
        for r in records.values()
        if r is not None
    )
    assert statuses == [
        ("no_such_frame", "error"),
        ("no_such_frame", "error"),
        ("panda_hand", "ok"),
    ]
    for record in records.values():
        assert record is not None
        if record["status"] == "error":
            assert "no_such_frame" in record["error"]


def test_set_reaches_list_items_by_index_name_or_type() -> None:
    from cbp.scenario import load_scenario

    boards = SCENARIOS / "cat_boards.yaml"
    scenario = load_scenario(
        boards,
        overrides={
            "constraints.contact_normals.gain": "0.5",  # by type (no name)
            "tasks.hand.params.max_step_translation": "0.006",  # by name
            "constraints.0.params.margin": "0.05",  # by index
        },
    )
    entries = {e.name: e for e in scenario.entries}
    assert entries["contact_normals"].gain == 0.5
    assert entries["hand"].plugin.params.max_step_translation == 0.006
    assert entries["joint_limits"].plugin.params.margin == 0.05
    with pytest.raises(ScenarioError, match="'constraints' has no item 'nope'"):
        load_scenario(boards, overrides={"constraints.nope.gain": "0.5"})


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            "samples: {{count: 2, values: {{duration: {{uniform: [-.inf, .inf]}}}}}}",
            "line 4: samples.values.duration: uniform: the bounds must be finite",
        ),
        (
            "samples: {{count: 2, values: {{duration: {{integers: [1, 2.5]}}}}}}",
            "line 4: samples.values.duration: integers: give [low, high], two integers",
        ),
        ("grid: {{duration: [2020-01-01]}}", "line 4: '2020-01-01' reads as a date"),
        (
            "samples: {{count: 1000000000000, values: {{duration: {{choice: [1]}}}}}}",
            "line 4: samples.count: must be in [1, 10000] draws",
        ),
        ("scenes: {{count: 100000000}}", "line 4: scenes.count: must be in [1, 1000]"),
        (
            "grid: {{" + ", ".join(f"k{i}: [1, 2, 3, 4]" for i in range(25)) + "}}",
            "line 4: grid: the sweep has 1125899906842624 runs",
        ),
        ("retries: 1000000", "line 4: retries: must be in [0, 100]"),
    ],
)
def test_sweep_sizes_and_bounds_are_checked_before_expansion(
    tmp_path: Path, body: str, message: str
) -> None:
    """Infinite bounds, dates and sizes past the limits are refused at their line."""
    path = _sweep(
        tmp_path,
        'name: s\nscenarios: ["{reach}"]\nmethods: [kinematic]\n' + body + "\n",
    )
    with pytest.raises(ScenarioError) as info:
        load_sweep(path)
    assert message in str(info.value)


def test_names_cannot_reach_outside_the_output_folder(tmp_path: Path) -> None:
    """A sweep's or a scenario's name with '../' is refused; nothing is written."""
    from cbp.cli import main

    work = tmp_path / "work"
    work.mkdir()
    path = _sweep(
        tmp_path,
        'name: ../../escaped\nscenarios: ["{reach}"]\nmethods: [kinematic]\n',
    )
    with pytest.raises(ScenarioError, match=r"line 1: name: must be one folder"):
        load_sweep(path)
    cwd = Path.cwd()
    os.chdir(work)
    try:
        assert main(["sweep", str(path)]) == 2
        assert main(["run", str(REACH), "--set", "name=../../escaped"]) == 2
        assert main(["run", str(REACH), "--set", "name=.hidden"]) == 2
    finally:
        os.chdir(cwd)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["sweep.yaml", "work"]


def test_a_large_sweep_expands_once_per_scenario_document(tmp_path: Path) -> None:
    """2500 runs expand with distinct ids, each override checked against the file."""
    values = ", ".join(str(1 + i / 100) for i in range(50))
    path = _sweep(
        tmp_path,
        f"""\
        name: large
        scenarios: ["{{reach}}"]
        methods: [kinematic]
        grid:
          duration: [{values}]
          method.kinematic.dt: [{", ".join(str(0.001 * (i + 1)) for i in range(50))}]
        """,
    )
    runs = expand(load_sweep(path), path, [])
    assert len({r.id for r in runs}) == 2500
    bad = _sweep(
        tmp_path,
        f"""\
        name: large
        scenarios: ["{{reach}}"]
        methods: [kinematic]
        grid:
          duration: [{values}]
          method.kinematic.dt: [0.01, 0.02, 5.0]
        """,
        "bad.yaml",
    )
    with pytest.raises(ScenarioError, match=r"--set method.kinematic.dt.*must be in"):
        expand(load_sweep(bad), bad, [])


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["pool", "ray"])
def test_hybrid_runs_in_virtual_time_repeat_exactly(
    tmp_path: Path, backend: str
) -> None:
    """Two hybrid runs of one scene, one after the other on one CPU, are identical.

    OMPL seeds its random numbers once per process: the second run is identical
    only if it gets a fresh worker process (ExecutorInfo.fresh_process).
    """
    path = tmp_path / "sweep.yaml"
    path.write_text(
        textwrap.dedent(
            f"""\
            name: hybrid_twice
            scenarios: ["{SCENARIOS / "cat_local_minimum.yaml"}"]
            methods: [hybrid]
            set: {{duration: 3.0}}
            grid:
              description: [first, second]
            clock: virtual
            """
        )
    )
    outcome = run_sweep(
        path, tmp_path / "out", workers=1, progress=False, backend=backend
    )
    assert outcome.failed == 0
    first, second = (tmp_path / "out" / "runs" / r.id for r in outcome.runs)
    events = json.loads((first / "metrics.json").read_text())["hybrid"]["events"]
    assert any("hybrid: planned" in e["message"] for e in events)  # OMPL ran
    assert (first / "trace.csv").read_bytes() == (second / "trace.csv").read_bytes()
    assert (first / "metrics.json").read_text() == (second / "metrics.json").read_text()
