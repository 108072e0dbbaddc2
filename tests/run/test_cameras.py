# SPDX-License-Identifier: Apache-2.0
"""A run's cameras say which of their frames the map holds, and what lies outside it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cbp.perception.kernels import OCCUPIED, UNKNOWN
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
        period = 1.0 / wrist.rate_hz

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


BELOW_FLOOR = """\
name: below_floor
include: cat
robot: {name: franka_panda}
duration: 1.0
goal: {type: keyframes, keyframes: [{t: 0.5, pose: {position: [0.5, 0.0, 0.07]}}]}
world:
  objects:
    - {name: box, shape: box, size: [0.2, 0.2, 0.1], pose: {position: [0.5, 0.0, -0.15]}}
"""


@pytest.mark.parametrize("bounds", ["configs/cat.yaml", "default"])
def test_surfaces_outside_the_bounds_are_said_and_the_default_covers_the_reach(
    tmp_path: Path, bounds: str
) -> None:
    """A box below cat.yaml's floor is said, once per camera; none by default.

    Without ``perception.bounds`` the map covers the box the arm can reach
    (the Panda's hand 0.86 m from its shoulder, with its fingers and padding
    about 1 m), which holds the box.
    """
    path = tmp_path / "below_floor.yaml"
    path.write_text(BELOW_FLOOR)
    overrides = {"perception.source": "depth_camera"}
    if bounds == "default":
        overrides["perception.bounds"] = "null"
    scenario = load_scenario(path, overrides=overrides)
    run = build_run(scenario, method="cat", clock="virtual")
    try:
        assert run.cameras is not None
        run.advance(0.2)
        grid = run.cameras.grid
        said = [m for _, m in run.log.events if "outside the map's bounds" in m]
    finally:
        run.close()
    if bounds == "default":
        assert said == []
        lower, upper = grid.bounds
        assert np.all(lower <= [-0.97, -0.97, -0.64])
        assert np.all(upper >= [0.97, 0.97, 1.30])
        assert grid.state_at(np.array([[0.5, 0.0, -0.099]]))[0] == OCCUPIED
        return
    cameras = {m.split("'")[1] for m in said}
    assert len(said) == len(cameras) >= 3  # once per camera that sees it
    assert all("[-1.0, -1.0, -0.05]" in m for m in said)
    assert grid.state_at(np.array([[0.5, 0.0, -0.099]]))[0] == UNKNOWN
