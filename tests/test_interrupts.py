"""Stop signals while outputs are written: noted, and obeyed only where they may."""

from __future__ import annotations

import signal

import pytest

from cbp.interrupts import Interrupted, SignalGuard


def test_a_guard_notes_signals_without_acting_on_them() -> None:
    """Inside a guard, Ctrl-C twice, SIGTERM and SIGHUP raise nothing; all noted."""
    told: list[str] = []
    before = signal.getsignal(signal.SIGTERM)
    with SignalGuard(told.append) as guard:
        for number in (signal.SIGINT, signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            signal.raise_signal(number)
    assert guard.received == ["SIGINT (Ctrl-C)", "SIGINT (Ctrl-C)", "SIGTERM", "SIGHUP"]
    assert told == guard.received
    assert signal.getsignal(signal.SIGTERM) is before  # put back


def test_a_signal_interrupts_only_inside_interruptible() -> None:
    """A signal raises Interrupted inside interruptible(); one left over, on entry."""
    with SignalGuard() as guard:
        with pytest.raises(Interrupted) as info, guard.interruptible():
            signal.raise_signal(signal.SIGTERM)
        assert info.value.name == "SIGTERM"
        signal.raise_signal(signal.SIGHUP)  # after the answer: only noted
        with pytest.raises(Interrupted, match="SIGTERM"), guard.interruptible():
            pass  # the first unanswered one, at once


def test_answered_signals_do_not_interrupt() -> None:
    """A signal a run's stop answered leaves the figures be; a later one does not."""
    with SignalGuard() as guard:
        signal.raise_signal(signal.SIGINT)
        guard.answered = 1
        with guard.interruptible():
            pass
        with pytest.raises(Interrupted, match="SIGINT"), guard.interruptible():
            signal.raise_signal(signal.SIGINT)
    assert guard.unanswered == ["SIGINT (Ctrl-C)"]


def test_deliver_acts_on_noted_signals_as_the_handlers_before_would() -> None:
    """Once removed, a guard delivers Ctrl-C to Python's own handler: KeyboardInterrupt."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with SignalGuard() as guard:
            signal.raise_signal(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt):
            guard.deliver()
        guard.deliver()  # delivered once only
    finally:
        signal.signal(signal.SIGINT, before)
