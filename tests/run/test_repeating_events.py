"""A repeating event is said once per episode, with its count."""

from __future__ import annotations

from cbp.run.events import EPISODE_GAP, Repeating


def test_an_episode_is_one_event_and_one_count() -> None:
    """Occurrences closer than the gap are counted; a quiet gap starts anew."""
    said: list[tuple[float, str]] = []
    eased = Repeating(lambda t, m: said.append((t, m)), "QP eased")
    for k in range(50):  # every 23 ms for 1.15 s
        eased.happened(0.023 * k, f"row {k % 3}")
    assert said == [(0.0, "QP eased: row 0")]
    eased.happened(0.023 * 49 + EPISODE_GAP + 0.1, "row 9")  # after a quiet gap
    assert said[1] == (0.023 * 49, "QP eased 49 more time(s) from 0.00 to 1.13 s")
    assert said[2][1] == "QP eased: row 9"
    eased.flush()  # a lone occurrence: nothing more to say
    assert len(said) == 3
    assert eased.total == 51
