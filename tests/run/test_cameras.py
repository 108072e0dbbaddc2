# SPDX-License-Identifier: Apache-2.0
"""A run's cameras say which of their frames the map holds."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from cbp.run.parts import build_run
from cbp.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@pytest.mark.parametrize("latency", [0.0, 0.1])
def test_frames_count_as_mapped_once_the_map_is_as_new_as_their_capture(
    latency: float,
) -> None:
    """A frame captured at or after ``t`` counts once a snapshot that new is in."""
    scenario = load_scenario(
        SCENARIOS / "cat_local_minimum.yaml",
        overrides={
            "perception.source": "depth_camera",
            "perception.virtual_latency": str(latency),
        },
    )
    run = build_run(scenario, method="cat", clock="virtual")
    try:
        assert run.cameras is not None
        wrist = next(c for c in run.cameras.cameras if c.name == "wrist")
        period = 1.0 / wrist.spec.rate_hz

        def captured(a: float, b: float) -> int:
            """The wrist camera's frames captured in [a, b] (at k periods)."""
            return max(
                0, math.floor(b / period + 1e-6) - math.ceil(a / period - 1e-6) + 1
            )

        start = 0.5
        run.advance(start)
        assert run.mapped_since("wrist", start) == captured(start, start - latency)
        end = start + 3.5 * period
        run.advance(end)
        assert captured(start, end) >= 3
        assert run.mapped_since("wrist", start) == captured(start, end - latency)
        run.advance(end + latency)
        assert run.mapped_since("wrist", start) == captured(start, end)
        assert run.mapped_since("overhead", end + 1.0) == 0
    finally:
        run.close()
