"""`cbp run` stopped by a signal: the robot brakes and the outputs are written."""

from __future__ import annotations

import os
import signal
import threading
from pathlib import Path

import pytest

from cbp.executors.cat import run_cat
from cbp.run.faults import (
    STOPPED_EARLY,
    Faults,
    clear_stop,
    request_stop,
    stop_on_signals,
)
from cbp.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@pytest.mark.parametrize(
    ("signum", "name"),
    [(signal.SIGTERM, "SIGTERM"), (signal.SIGINT, "SIGINT (Ctrl-C)")],
)
def test_a_signal_asks_every_run_to_stop(signum: int, name: str) -> None:
    """Inside stop_on_signals a signal is a stop request; outside, nothing is kept."""
    events: list[tuple[float, str]] = []
    faults = Faults(lambda t, m: events.append((t, m)))
    with stop_on_signals():
        assert faults.aborted is None
        os.kill(os.getpid(), signum)
        assert faults.aborted == f"{STOPPED_EARLY}: {name}"
    assert Faults(lambda t, m: None).aborted is None  # cleared on the way out
    assert signal.getsignal(signal.SIGTERM) is not None


def test_a_second_sigint_interrupts_at_once() -> None:
    """Ctrl-C twice: the first asks to stop, the second interrupts."""
    with stop_on_signals():
        os.kill(os.getpid(), signal.SIGINT)
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)


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
