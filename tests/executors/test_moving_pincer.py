"""Generated moving scene 3, seen by the cameras: a pincer closing on the arm."""

from __future__ import annotations

import pytest

from cbp.executors.cat import run_cat
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario
from cbp.scenes import write_scenes


@pytest.mark.slow
@pytest.mark.parametrize("latency", [0.0, 0.1])
def test_a_pincer_of_moving_obstacles_is_outrun_with_the_cameras(
    tmp_path, latency: float
) -> None:
    """Generated scene 3: a ball and a post close on the arm from two sides.

    Virtual time, with the map's snapshots at once and 0.1 s late (as a map in
    its own process delivers them in wall-clock runs, whose outcome depends on
    the machine's load, which a test's must not: they are tabulated in
    docs/moving_scenes.md). With the cameras the map's moving cells are
    measured ahead and the arm retreats into its own shadow: 0 N, as with the
    declared objects. Without them (``moving_speed: 0``) the arm was pinned
    between the obstacles and unseen space (1.4 MN); with snapshots 67 ms late,
    before unseen space was read from the newest map's states, 15 kN.
    """
    (path,) = write_scenes(tmp_path, 1, seed=3, moving=True)
    assert path.stem == "moving_3"
    seen = {
        "method.cat.timing.clock": "virtual",
        "perception.source": "depth_camera",
        "perception.virtual_latency": str(latency),
    }
    trace = run_cat(load_scenario(path, overrides=seen))
    assert run_metrics(trace)["peak_contact_force_n"] == 0.0
    assert any("the cameras see moving" in message for _, message in trace.events)
