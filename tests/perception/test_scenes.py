"""The scene generators: seeded, valid files, safe with both sources."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from cbp.executors.cat import run_cat
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario
from cbp.scenes import generate_moving_scene, generate_scene, write_scenes
from tests.conftest import VIRTUAL_CLOCK


def test_a_seed_gives_one_scene_and_seeds_differ() -> None:
    assert generate_scene(4) == generate_scene(4)
    assert generate_scene(4) != generate_scene(5)
    kinds = {
        o["shape"] for s in range(20) for o in generate_scene(s)["world"]["objects"]
    }
    assert kinds == {"box", "cylinder", "sphere"}


def test_written_scenes_load_and_start_clear(tmp_path) -> None:
    paths = write_scenes(tmp_path, 3, seed=0)
    assert len(paths) == 3
    for path in paths:
        scenario = load_scenario(path)  # refused if the arm starts in contact
        world = scenario.world_for_run()
        assert world.check(scenario.q0).penetration == 0.0
        assert 3 <= len(scenario.spec.world.objects) - 1 <= 7


@pytest.mark.slow
@pytest.mark.parametrize("source", ["ground_truth", "depth_camera"])
def test_generated_scenes_run_without_contact(tmp_path, source) -> None:
    """Two generated clutter scenes at 0 N (virtual clock: load-independent)."""
    for path in write_scenes(tmp_path, 2, seed=100):
        overrides = {"perception.source": source, **VIRTUAL_CLOCK}
        scenario = load_scenario(path, overrides=overrides)
        m = run_metrics(run_cat(scenario))
        assert m["peak_contact_force_n"] == 0.0, (path.name, m)


def test_moving_scenes_come_at_the_hand_at_2_to_20_cm_s(tmp_path) -> None:
    """Seeded; every object moves toward the held hand and stops past its reach."""
    assert generate_moving_scene(3) == generate_moving_scene(3)
    assert generate_moving_scene(3) != generate_moving_scene(4)
    kinds = set()
    for path in write_scenes(tmp_path, 4, seed=0, moving=True):
        scenario = load_scenario(path)  # refused if the arm starts in contact
        document = yaml.safe_load(path.read_text())
        hand = np.array(document["goal"]["keyframes"][0]["pose"]["position"])
        movers = document["world"]["objects"][1:]
        assert 1 <= len(movers) <= 3
        for o in movers:
            kinds.add(o["shape"])
            v = np.array(o["motion"]["velocity"])
            assert 0.0199 <= np.linalg.norm(v) <= 0.2001
            start = np.array(o["pose"]["position"])
            duration = o["motion"]["stop"] - o["motion"]["start"]
            end = start + v * duration
            # Toward the hand, and ending nearer to it than it started.
            assert v.dot(hand - start) > 0.0
            assert np.linalg.norm(end - hand) < np.linalg.norm(start - hand)
            assert end[2] > 0.0  # never into the table
        assert scenario.spec.duration >= max(o["motion"]["stop"] for o in movers)
    assert kinds <= {"box", "sphere", "cylinder"}
