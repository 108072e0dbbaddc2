"""A run's trace and metrics survive every stop; a session never replaces another."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from cbp.errors import ConfigError
from cbp.files import claim_new_output_folder, claim_output_folder

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
#: What ``cbp -v run`` logs once the trace and metrics are in place.
RECORD_WRITTEN = "trace and metrics written; drawing the figures"


def _run_signalled(
    out: Path, duration: str, plan: list[tuple[str, str]]
) -> tuple[int, str]:
    """``cbp -v run`` of the Panda's reach; each (line, signal) of ``plan`` in turn.

    The signal is sent as soon as the run prints a line holding the text;
    returns the exit status and everything it printed.
    """
    command = [
        sys.executable,
        "-m",
        "cbp",
        "-v",
        "run",
        str(SCENARIOS / "panda_reach.yaml"),
        "--out",
        str(out),
        "--set",
        f"duration={duration}",
    ]
    said = []
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    ) as process:
        watchdog = threading.Timer(600.0, process.kill)  # a hung run fails
        watchdog.start()
        try:
            assert process.stdout is not None
            for line in process.stdout:
                said.append(line)
                if plan and plan[0][0] in line:
                    process.send_signal(getattr(signal, plan.pop(0)[1]))
        finally:
            watchdog.cancel()
    assert not plan, f"not sent: {plan}\n{''.join(said)}"
    return process.returncode, "".join(said)


@pytest.mark.parametrize(
    ("duration", "plan", "aborted"),
    [
        ("1", [(RECORD_WRITTEN, "SIGTERM")], None),
        ("1", [(RECORD_WRITTEN, "SIGHUP")], None),
        # Ctrl-C stops the run; a second one while the outputs are written.
        (
            "30",
            [(" of 30.0 s", "SIGINT"), (RECORD_WRITTEN, "SIGINT")],
            "stopped early: SIGINT (Ctrl-C)",
        ),
    ],
    ids=["SIGTERM", "SIGHUP", "SIGINT-twice"],
)
def test_a_signal_while_outputs_are_written_keeps_trace_and_metrics(
    tmp_path: Path, duration: str, plan: list[tuple[str, str]], aborted: str | None
) -> None:
    """The figures and the report are cut short (exit 130); trace and metrics load."""
    out = tmp_path / "out"
    signal_name = plan[-1][1]
    status, said = _run_signalled(out, duration, list(plan))
    assert status == 130, said
    metrics = json.loads((out / "metrics.json").read_text())["kinematic"]
    assert metrics["aborted"] == aborted
    assert metrics["incomplete"] == ["plots", "scene figure", "report"]
    messages = [e["message"] for e in metrics["events"]]
    assert f"plots not written: Interrupted: {signal_name}" in messages[0], messages
    trace = np.loadtxt(out / "trace.csv", delimiter=",", skiprows=1, ndmin=2)
    assert trace.shape[0] == metrics["samples"] > 0
    assert np.isfinite(trace).all()
    assert not (out / "report.md").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # nothing staged
    assert "not written: plots, scene figure, report" in said


def test_a_session_folder_is_never_replaced(tmp_path: Path) -> None:
    """Refused when given (exit 2, untouched); a fresh one when left to choose."""
    from cbp.cli import main

    earlier = tmp_path / "boards_teleop"
    earlier.mkdir()
    (earlier / "metrics.json").write_text("{}")
    (earlier / "operator_goal.csv").write_text("t,x\n")
    boards = str(SCENARIOS / "cat_boards.yaml")
    assert main(["teleop", boards, "--out", str(earlier)]) == 2
    assert sorted(p.name for p in earlier.iterdir()) == [
        "metrics.json",
        "operator_goal.csv",
    ]
    with pytest.raises(ConfigError, match="is not empty; choose a new or empty"):
        claim_output_folder(earlier, replace=False)
    fresh = claim_new_output_folder(earlier)
    try:
        assert fresh.out == tmp_path / "boards_teleop_2"
        third = claim_new_output_folder(earlier)  # _2 is claimed by a live session
        assert third.out == tmp_path / "boards_teleop_3"
        third.release(remove=True)
    finally:
        fresh.release(remove=True)


def test_a_published_output_replaced_meanwhile_takes_no_more_files(
    tmp_path: Path,
) -> None:
    """After a later run replaces the folder, an earlier one's figures never mix in."""
    out = tmp_path / "out"
    first = claim_output_folder(out, refuse_live=False)
    (first.staging / "metrics.json").write_text('{"first": {}}')
    first.publish()
    second = claim_output_folder(out, refuse_live=False)
    (second.staging / "metrics.json").write_text('{"second": {}}')
    second.publish()
    (first.staging / "tracking.png").write_text("first's figure")
    assert not first.put("tracking.png")
    (second.staging / "report.md").write_text("second's report")
    assert second.put("report.md")
    for claim in (first, second):
        claim.release(remove=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "report.md"]
    assert json.loads((out / "metrics.json").read_text()) == {"second": {}}
