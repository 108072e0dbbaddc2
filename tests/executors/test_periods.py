"""The adaptive period settles at what the machine sustains; misses are counted."""

from __future__ import annotations

import pytest

from cbp.executors.periods import (
    FLOOR_HOLD,
    DeadlineMisses,
    LeadAdapter,
    PeriodAdapter,
)


def _misses(adapter: PeriodAdapter, seconds: float) -> int:
    """Misses of a loop that converges for 3 periods, then works for 1.

    Working, the planner fills its 80 % budget and the machine adds 6 ms the
    budget does not see (a loaded machine); converged, it takes 2 ms.
    """
    period, t, k, missed_count = 0.015, 0.0, 0, 0
    while t < seconds:
        compute = 0.8 * period + 0.006 if k % 4 == 3 else 0.002
        missed = compute > period
        missed_count += missed
        period = adapter.next(t, period, compute, missed)
        t += period
        k += 1
    return missed_count


def test_the_period_does_not_shrink_back_below_a_missed_one() -> None:
    """Misses held to about one per FLOOR_HOLD, not one in every working period."""
    settled = _misses(PeriodAdapter(0.015, 0.133, growth=1.5, shrink=0.9), 30.0)
    assert settled <= 2 * (1 + int(30.0 / FLOOR_HOLD))


def test_without_the_floor_the_period_oscillates(monkeypatch) -> None:
    """The same loop with no hold misses in most working periods."""
    from cbp.executors import periods

    monkeypatch.setattr(periods, "FLOOR_HOLD", 0.0)
    oscillating = _misses(PeriodAdapter(0.015, 0.133, growth=1.5, shrink=0.9), 30.0)
    assert oscillating > 100


def test_the_floor_is_released_after_the_hold() -> None:
    """Once the machine keeps up for FLOOR_HOLD, the period shrinks to the shortest."""
    adapter = PeriodAdapter(0.015, 0.133, growth=1.5, shrink=0.9)
    period = adapter.next(0.0, 0.015, 0.02, missed=True)
    assert period == pytest.approx(0.0225)
    assert adapter.next(1.0, period, 0.001, missed=False) == pytest.approx(0.0225)
    t = FLOOR_HOLD + 0.1
    for _ in range(50):
        period = adapter.next(t, period, 0.001, missed=False)
        t += period
    assert period == pytest.approx(0.015)


def test_a_run_of_misses_is_said_in_a_few_events() -> None:
    """1000 misses in 15 s: the first at once, then at most one a second."""
    said: list[tuple[float, str]] = []
    misses = DeadlineMisses(lambda t, m: said.append((t, m)))
    for k in range(1000):
        misses.missed(k * 0.015, 0.02, 0.015, "result discarded")
    misses.met(15.0)
    assert misses.total == 1000
    assert said[0][1].startswith("deadline missed (20.0 ms for a 15.0 ms period)")
    assert len(said) <= 17
    counted = sum(int(m.split(" in ")[1].split()[0]) for _, m in said[1:])
    assert counted == 999
    assert said[-1][1].endswith("deadlines met again")


def test_a_single_miss_is_one_event() -> None:
    """An isolated miss is said once, with its figures; meeting again adds nothing."""
    said: list[tuple[float, str]] = []
    misses = DeadlineMisses(lambda t, m: said.append((t, m)))
    misses.missed(1.0, 0.04, 0.033, "result discarded")
    misses.met(1.033)
    misses.flush(2.0)
    assert [m for _, m in said] == [
        "deadline missed (40.0 ms for a 33.0 ms period): result discarded"
    ]


def test_the_lead_grows_after_a_late_plan_and_shrinks_back_within_its_bounds() -> None:
    """Late: times growth, up to the longest; in time: times shrink, to the shortest."""
    leads = LeadAdapter(0.006, 0.024, growth=1.5, shrink=0.9)
    assert leads.lead == 0.006
    leads.planned(in_time=False)
    assert leads.lead == pytest.approx(0.009)
    for _ in range(10):
        leads.planned(in_time=False)
    assert leads.lead == 0.024
    leads.planned(in_time=True)
    assert leads.lead == pytest.approx(0.0216)
    for _ in range(50):
        leads.planned(in_time=True)
    assert leads.lead == 0.006
