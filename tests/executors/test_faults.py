"""Faults injected into normal runs: every run ends with its outputs and says why.

Each test breaks one part of a run that otherwise works (a plugin, the planner,
the goal input, a camera, the simulator) by monkeypatching it, and checks that
the run finishes with all its outputs, the event in the report, no joint past
its limits and no contact force caused by the fault.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from cbp.executors import cat as cat_module
from cbp.executors.cat import run_cat
from cbp.executors.kinematic import run_kinematic
from cbp.executors.velocity import run_velocity
from cbp.goals import KeyframesGoal
from cbp.metrics import run_metrics
from cbp.perception.frame import DepthFrame
from cbp.report import write_outputs
from cbp.run.faults import EXIT_ABORTED, MAX_FAULTS_IN_A_ROW
from cbp.run.goal_input import GoalInput
from cbp.scenario import Scenario
from cbp.sim.camera import DepthCamera
from cbp.sim.recorder import Recorder
from tests.conftest import load_virtual, run_cbp

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"


class InjectedError(RuntimeError):
    """The injected fault."""


def _events(trace) -> str:
    return "\n".join(m for _, m in trace.events)


def _raise_in_engine(monkeypatch, when) -> None:
    """Every engine the scenario makes raises InjectedError on the steps ``when`` picks."""
    original = Scenario.make_engine

    def make_engine(self, *args, **kwargs):
        engine = original(self, *args, **kwargs)
        step = engine.step
        calls = [0]

        def faulty(q, dt, *args):
            calls[0] += 1
            if when(calls[0]):
                raise InjectedError("injected")
            return step(q, dt, *args)

        engine.step = faulty
        return engine

    monkeypatch.setattr(Scenario, "make_engine", make_engine)


def test_kinematic_run_holds_through_a_raising_step_and_goes_on(monkeypatch) -> None:
    _raise_in_engine(monkeypatch, lambda k: k % 50 == 0)
    scenario = load_virtual(SCENARIOS / "panda_reach.yaml")
    trace = run_kinematic(scenario)
    m = run_metrics(trace, scenario.robot)
    assert m["aborted"] is None
    assert trace.t[-1] == pytest.approx(scenario.spec.duration)
    assert "control step failed (InjectedError: injected); robot held" in _events(trace)
    assert m["reached"], m
    assert m["max_joint_limit_violation_rad"] == 0.0


def test_kinematic_run_aborts_after_faults_in_a_row_and_writes_everything(
    monkeypatch, tmp_path: Path
) -> None:
    _raise_in_engine(monkeypatch, lambda k: k > 100)
    scenario = load_virtual(SCENARIOS / "panda_reach.yaml")
    trace = run_kinematic(scenario)
    assert trace.aborted is not None
    assert f"failed {MAX_FAULTS_IN_A_ROW} times in a row" in trace.aborted
    # The robot held from the first fault on: it did not move after it.
    assert trace.t.size == 100 + MAX_FAULTS_IN_A_ROW
    assert np.allclose(trace.q[100:], trace.q[100])
    metrics = write_outputs(scenario, {"kinematic": trace}, tmp_path / "out")
    assert metrics["kinematic"]["aborted"] == trace.aborted
    written = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert written["kinematic"]["aborted"] == trace.aborted
    assert "run aborted" in (tmp_path / "out" / "report.md").read_text()
    assert (tmp_path / "out" / "trace.csv").exists()


def test_cbp_run_exits_with_the_aborted_code(tmp_path: Path) -> None:
    """A plugin that raises every step: exit 3, all outputs written."""
    plugin = tmp_path / "raising_task.py"
    plugin.write_text(
        "from cbp.plugins.tasks.posture_task import PostureTask\n"
        "class RaisingTask(PostureTask):\n"
        "    type_name = 'raising'\n"
        "    def compute_value(self, state):\n"
        "        raise RuntimeError('plugin bug')\n"
        "    def value_into(self, state, out):\n"
        "        raise RuntimeError('plugin bug')\n"
    )
    text = (SCENARIOS / "panda_reach.yaml").read_text()
    scenario = tmp_path / "s.yaml"
    scenario.write_text(text.replace("type: posture", "type: raising_task:RaisingTask"))
    out = tmp_path / "out"
    done = run_cbp("run", str(scenario), "--out", str(out))
    assert done.returncode == EXIT_ABORTED, done.stderr
    assert "ABORTED" in done.stdout
    metrics = json.loads((out / "metrics.json").read_text())["kinematic"]
    assert "RuntimeError: plugin bug" in metrics["aborted"]
    assert (out / "report.md").exists()
    assert (out / "trace.csv").exists()


def test_cat_holds_through_a_raising_planner_without_contact(monkeypatch) -> None:
    """The planner raises for 0.15 s mid-move: the arm brakes, then goes on."""
    plan = cat_module.CatPlanner.plan

    def faulty(self, q, goal, budget, run):
        if 0.8 <= run.arm.t < 0.95:
            raise InjectedError("planner bug")
        return plan(self, q, goal, budget, run)

    monkeypatch.setattr(cat_module.CatPlanner, "plan", faulty)
    scenario = load_virtual(SCENARIOS / "cat_boards.yaml", overrides={"duration": "4"})
    trace = run_cat(scenario)
    m = run_metrics(trace, scenario.robot)
    assert "planning failed (InjectedError: planner bug); robot held" in _events(trace)
    assert m["aborted"] is None
    assert m["peak_contact_force_n"] == 0.0
    assert m["max_joint_limit_violation_rad"] == 0.0
    # The arm was moving fast; while the planner failed it braked.
    speed = np.linalg.norm(np.diff(trace.q, axis=0), axis=1) / np.diff(trace.t)
    before = (trace.t[1:] > 0.7) & (trace.t[1:] < 0.8)
    late = (trace.t[1:] > 0.92) & (trace.t[1:] < 0.96)
    assert speed[before].max() > 0.3
    assert speed[late].max() < 0.25 * speed[before].max()


def test_cat_aborts_when_the_simulator_keeps_failing(monkeypatch) -> None:
    scenario = load_virtual(
        SCENARIOS / "cat_free_step.yaml", overrides={"duration": "2"}
    )
    from cbp.run import RunParts

    advance = RunParts.advance

    def faulty(self, t, look_ahead=0.0):
        if t > 1.0 and t < 1.9:
            raise InjectedError("physics")
        return advance(self, t, look_ahead)

    monkeypatch.setattr(RunParts, "advance", faulty)
    trace = run_cat(scenario)
    assert trace.aborted is not None
    assert "simulation failed" in trace.aborted
    m = run_metrics(trace, scenario.robot)
    assert m["max_joint_limit_violation_rad"] == 0.0


def test_a_goal_input_that_raises_keeps_the_previous_goal(monkeypatch) -> None:
    sample = KeyframesGoal.sample  # the step goal of cat_free_step samples so

    def faulty(self, t):
        if 1.0 <= t < 1.5:
            raise InjectedError("device unplugged")
        return sample(self, t)

    monkeypatch.setattr(KeyframesGoal, "sample", faulty)
    scenario = load_virtual(
        SCENARIOS / "cat_free_step.yaml", overrides={"duration": "2.5"}
    )
    trace = run_cat(scenario)
    events = _events(trace)
    assert (
        "goal input failed (InjectedError: device unplugged); previous goal kept"
        in events
    )
    assert "goal input works again" in events
    assert events.count("goal input failed") == 1  # once per outage, not per sample
    assert trace.aborted is None
    assert run_metrics(trace, scenario.robot)["reached"]


def test_the_velocity_executor_brakes_the_base_when_it_aborts(monkeypatch) -> None:
    _raise_in_engine(monkeypatch, lambda k: k > 20)
    scenario = load_virtual(SCENARIOS / "youbot_pan.yaml", overrides={"duration": "3"})
    trace = run_velocity(scenario)
    assert trace.aborted is not None
    assert trace.u is not None
    # From the first fault on, every command brakes within the acceleration
    # limits (the robot cannot stop at once), and the base comes to rest.
    braking = scenario.robot.acceleration_limits * 0.02 * (1 + 1e-9)
    after = np.abs(trace.u[20:])
    assert np.all(np.diff(after, axis=0) <= 1e-12)
    assert np.all(np.abs(np.diff(trace.u[20:], axis=0)) <= braking)
    assert np.all(after[-1] == 0.0)


# ------------------------------------------------------------------ cameras


def _blind_after(monkeypatch, t_blind: float, kind: str) -> None:
    """Cameras give bad frames (or raise) from simulated time ``t_blind`` on."""
    capture = DepthCamera.capture
    clock = {"t": 0.0}
    from cbp.sim.simulation import Simulation

    step = Simulation.step

    def tracking(self):
        step(self)
        clock["t"] = self.t

    last: dict[str, DepthFrame] = {}

    def faulty(self, state=None):
        frame = capture(self, state)
        if clock["t"] < t_blind:
            last[self.name] = frame
            return frame
        if kind == "raise":
            raise InjectedError("camera unplugged")
        if kind == "frozen":  # a stuck driver repeats its last frame
            return last[self.name]
        if kind == "bumped" and not self.mounted:  # turned, but claims its pose
            turned = dataclasses.replace(
                self.spec, target=tuple(np.add(self.spec.target, (0.0, 0.6, 0.0)))
            )
            seen = capture(DepthCamera(self.client, turned, None))
            return dataclasses.replace(seen, view=frame.view, camera=frame.camera)
        if kind == "bumped":
            return frame
        fill = {"nan": np.nan, "zero": 0.0, "far": 1.0}[kind]
        depth = np.full_like(frame.depth, fill)
        return DepthFrame(
            depth, frame.view, frame.projection, frame.near, frame.far, frame.camera
        )

    monkeypatch.setattr(Simulation, "step", tracking)
    monkeypatch.setattr(DepthCamera, "capture", faulty)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["nan", "zero", "raise", "far", "frozen", "bumped"])
def test_a_blinded_camera_is_an_event_and_stops_the_arm(monkeypatch, kind) -> None:
    """Bad frames from t = 0.5 s: dropped, the arm stops within the timeout.

    Malformed frames (NaN, zero), a camera that raises, and frames that are
    well formed but lie: nothing up to the far plane, the last frame again
    while the arm moves, a fixed camera turned away that claims its old pose.
    """
    _blind_after(monkeypatch, 0.5, kind)
    scenario = load_virtual(
        SCENARIOS / "cat_boards.yaml",
        overrides={"duration": "3", "perception.source": "depth_camera"},
    )
    trace = run_cat(scenario)
    events = _events(trace)
    assert "frame dropped" in events
    assert "robot stopped" in events
    m = run_metrics(trace, scenario.robot)
    assert m["peak_contact_force_n"] == 0.0
    assert m["max_joint_limit_violation_rad"] == 0.0
    stop = scenario.spec.perception.camera_timeout + 0.5 + 0.5  # and braking
    still = trace.t > stop
    assert np.max(np.abs(np.diff(trace.q[still], axis=0))) < 1e-4


def test_frame_problems_name_what_is_wrong() -> None:
    view = np.eye(4)
    good = DepthFrame(np.full((8, 8), 0.5), view, view, 0.1, 3.0)
    assert good.problem(0.2) is None
    empty = DepthFrame(np.ones((8, 8)), view, view, 0.1, 3.0)  # all far: sees free
    assert empty.problem(0.2) is None
    nan = DepthFrame(np.full((8, 8), np.nan), view, view, 0.1, 3.0)
    assert "0% of its pixels" in (nan.problem(0.2) or "")
    zero = DepthFrame(np.zeros((8, 8)), view, view, 0.1, 3.0)
    assert "0% of its pixels" in (zero.problem(0.2) or "")
    bad_pose = DepthFrame(np.full((8, 8), 0.5), view * np.nan, view, 0.1, 3.0)
    assert bad_pose.problem(0.2) == "camera pose not finite"


# ------------------------------------------------------------------ outputs


def test_a_folder_in_use_by_a_live_run_is_refused_and_a_dead_ones_is_cleaned(
    tmp_path: Path,
) -> None:
    """A live claim on --out refuses a second run (exit 2); a killed one's is removed."""
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from pathlib import Path; "
            "from cbp.files import claim_output_folder; "
            "print(claim_output_folder(Path(sys.argv[1])).staging, flush=True); "
            "time.sleep(600)",
            str(out),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None
        staging = Path(holder.stdout.readline().strip())
        assert staging.is_dir()
        refused = run_cbp("run", str(SCENARIOS / "panda_reach.yaml"), "--out", str(out))
        assert refused.returncode == 2
        assert f"output folder {out} is in use by a run still going" in refused.stderr
        assert f"process {holder.pid}" in refused.stderr
    finally:
        holder.kill()  # SIGKILL: nothing of its own cleans up
        holder.communicate()
    assert staging.is_dir()  # what a killed run leaves
    done = run_cbp(
        "run",
        str(SCENARIOS / "panda_reach.yaml"),
        "--out",
        str(out),
        "--set",
        "duration=1",
    )
    assert done.returncode == 0, done.stderr
    assert (out / "metrics.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no lock file


def test_outputs_never_replace_a_folder_that_is_not_an_output(tmp_path: Path) -> None:
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "thesis.tex").write_text("precious")
    done = run_cbp("run", str(SCENARIOS / "panda_reach.yaml"), "--out", str(folder))
    assert done.returncode == 2
    assert "not a cbp output" in done.stderr
    assert (folder / "thesis.tex").read_text() == "precious"


def test_write_outputs_publishes_whole_folders_under_threads(tmp_path: Path) -> None:
    scenario = load_virtual(SCENARIOS / "panda_reach.yaml", overrides={"duration": "1"})
    trace = run_kinematic(scenario)
    out = tmp_path / "out"
    errors: list[BaseException] = []

    def write() -> None:
        try:
            write_outputs(scenario, {"kinematic": trace}, out)
        except BaseException as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=write) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors
    assert {p.name for p in out.iterdir()} >= {"metrics.json", "report.md", "trace.csv"}


def test_the_recorder_spools_blocks_and_reads_them_back() -> None:
    recorder = Recorder(3, block_rows=4)
    expected = np.arange(30.0).reshape(10, 3)
    for row in expected:
        recorder.row()[:] = row
    assert len(recorder) == 10
    assert np.array_equal(recorder.array(), expected)
    recorder.row()[:] = [1, 2, 3]  # recording goes on after a read
    assert np.array_equal(recorder.array()[-1], [1, 2, 3])
    recorder.close()


def test_a_collision_checker_that_fails_for_good_still_gives_every_output(
    monkeypatch, tmp_path: Path
) -> None:
    """From its 200th call on the checker raises: the run aborts, outputs written."""
    from cbp.cli import main
    from cbp.collision.world import CollisionWorld

    check = CollisionWorld.check
    calls = [0]

    def failing(self, *args, **kwargs):
        calls[0] += 1
        if calls[0] >= 200:
            raise InjectedError("checker gone")
        return check(self, *args, **kwargs)

    monkeypatch.setattr(CollisionWorld, "check", failing)
    out = tmp_path / "out"
    status = main(
        [
            "run",
            str(SCENARIOS / "cat_boards.yaml"),
            "--out",
            str(out),
            "--set",
            "duration=2",
            "--set",
            "method.cat.timing.clock=virtual",
        ]
    )
    assert calls[0] > 200
    assert status == EXIT_ABORTED
    document = json.loads((out / "metrics.json").read_text())["cat"]
    messages = [e["message"] for e in document["events"]]
    assert "clearance not computed: InjectedError: checker gone" in messages
    assert document["incomplete"] == ["clearance"]
    assert "InjectedError: checker gone" in document["aborted"]
    for name in ("report.md", "trace.csv", "scene.json", "tracking.png"):
        assert (out / name).is_file(), name


@pytest.mark.parametrize(
    ("target", "stage"),
    [
        ("cbp.report.plot_runs", "plots"),
        ("cbp.report.run_metrics", "metrics"),
        ("cbp.report.write_scene", "scene description"),
        ("cbp.report._report", "report"),
    ],
)
def test_a_failing_output_stage_is_an_event_and_exit_4(
    monkeypatch, tmp_path: Path, target: str, stage: str
) -> None:
    """Each stage after the loop that raises is named; the rest is written."""
    from cbp.cli import main
    from cbp.run.faults import EXIT_INCOMPLETE

    def broken(*args, **kwargs):
        raise InjectedError("stage bug")

    monkeypatch.setattr(target, broken)
    out = tmp_path / "out"
    reach = str(SCENARIOS / "panda_reach.yaml")
    assert main(["run", reach, "--out", str(out), "--set", "duration=1"]) == (
        EXIT_INCOMPLETE
    )
    document = json.loads((out / "metrics.json").read_text())["kinematic"]
    assert document["incomplete"] == [stage]
    messages = [e["message"] for e in document["events"]]
    assert f"{stage} not written: InjectedError: stage bug" in messages
    assert (out / "trace.csv").is_file()
    assert (out / "report.md").is_file()


# ------------------------------------------------------------------ IK's guard


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (lambda q, robot: np.full_like(q, np.nan), "not 7 finite values"),
        (
            # the elbow 0.5 rad past its upper limit
            lambda q, robot: np.where(
                np.arange(q.size) == 3, robot.upper_limits + 0.5, q
            ),
            "panda_joint4 would end",
        ),
    ],
    ids=["nan", "past_limit"],
)
def test_ik_holds_through_bad_solutions_and_aborts_when_they_persist(
    monkeypatch, bad, message
) -> None:
    """Bad IK solutions are refused by IK's step guard: held, then aborted."""
    from cbp.executors.ik import run_ik
    from cbp.executors.ik_search import IkSearch

    solution_for = IkSearch.solution_for
    window = [0.8, 0.95]

    def faulty(self, goal, q_near, budget):
        solution = solution_for(self, goal, q_near, budget)
        if solution is not None and window[0] <= self_time[0] < window[1]:
            return bad(solution, self.robot)
        return solution

    self_time = [0.0]
    send_goal = GoalInput.send

    def timed(self, t):
        self_time[0] = t
        return send_goal(self, t)

    monkeypatch.setattr(IkSearch, "solution_for", faulty)
    monkeypatch.setattr(GoalInput, "send", timed)
    overrides = {"duration": "3", "method.ik.timing.clock": "virtual"}
    scenario = load_virtual(SCENARIOS / "cat_free_step.yaml", overrides=overrides)
    trace = run_ik(scenario)
    m = run_metrics(trace, scenario.robot)
    assert f"planning failed (UnsafeStepError: IK solution rejected: {message}" in (
        _events(trace)
    )
    assert m["aborted"] is None
    assert m["max_joint_limit_violation_rad"] == 0.0
    assert np.all(np.isfinite(trace.q))
    # Refused for good: the run is aborted, still within the limits.
    window[1] = 10.0
    trace = run_ik(load_virtual(SCENARIOS / "cat_free_step.yaml", overrides=overrides))
    m = run_metrics(trace, scenario.robot)
    assert "IK solution rejected" in m["aborted"]
    assert m["max_joint_limit_violation_rad"] == 0.0
    assert np.all(np.isfinite(trace.q))
