"""`cbp run` stopped by a signal: the robot brakes and the outputs are written."""

from __future__ import annotations

import threading
from pathlib import Path

from cbp.executors.cat import run_cat
from cbp.run.faults import (
    STOPPED_EARLY,
    clear_stop,
    request_stop,
)
from cbp.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def test_a_run_asked_to_stop_brakes_and_keeps_what_it_did() -> None:
    """The free step stopped 1 s in: a trace up to about there, said aborted."""
    scenario = load_scenario(
        SCENARIOS / "cat_free_step.yaml",
        overrides={"method.cat.timing.clock": "virtual", "duration": "60"},
    )
    stopper = threading.Timer(1.0, request_stop, args=("a test",))
    stopper.start()
    try:
        trace = run_cat(scenario)
    finally:
        stopper.cancel()
        clear_stop()
    assert trace.aborted == f"{STOPPED_EARLY}: a test"
    assert trace.t[-1] < 59.0
    assert trace.events[-1][1] == (
        f"run {STOPPED_EARLY}: a test: the outputs hold it up to here"
    )
    # Braked: at rest at the end.
    assert abs(trace.q[-1] - trace.q[-2]).max() < 1e-3
