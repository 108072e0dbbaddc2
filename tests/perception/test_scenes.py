"""The cluttered-scene generator: seeded, valid files, safe with both sources."""

from __future__ import annotations

import pytest

from cbp.executors.cat import run_cat
from cbp.metrics import run_metrics
from cbp.scenario import load_scenario
from cbp.scenes import generate_scene, write_scenes


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
    for path in write_scenes(tmp_path, 2, seed=100):
        scenario = load_scenario(path, overrides={"perception.source": source})
        m = run_metrics(run_cat(scenario))
        assert m["peak_contact_force_n"] == 0.0, (path.name, m)
