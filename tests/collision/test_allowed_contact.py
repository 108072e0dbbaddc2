"""Wanted contact: links allowed to touch an object are not kept off it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cbp.errors import ScenarioError
from cbp.executors.kinematic import run_kinematic
from cbp.scenario import load_scenario

PUSH = Path(__file__).resolve().parents[2] / "scenarios" / "panda_push_box.yaml"
HAND = "[panda_hand, panda_leftfinger, panda_rightfinger]"


def _run(allow: str | None):
    overrides = {"duration": "3"}
    if allow is not None:
        overrides["world.objects.box.allow_contact"] = allow
    scenario = load_scenario(PUSH, overrides=overrides)
    return scenario, run_kinematic(scenario)


def test_the_hand_allowed_to_touch_the_box_goes_into_it() -> None:
    _, kept_off = _run(None)
    scenario, allowed = _run(HAND)
    # Kept off, the hand stops on the face; allowed, it follows the goal down.
    assert allowed.ee_position[:, 2].min() < kept_off.ee_position[:, 2].min() - 0.02
    # There the fingers are in the box: contacts for the strict world, none for
    # the one that allows them; the other links are still kept off it.
    q = allowed.q[int(np.argmin(allowed.ee_position[:, 2]))]
    fingers = {"panda_hand", "panda_leftfinger", "panda_rightfinger"}

    def touching(world) -> set[str]:
        c = world.check(q).contacts
        return {world.geometry.shapes[i].link for i in c.shape[c.distance < 0]}

    assert touching(load_scenario(PUSH).world_for_run()) & fingers
    assert not touching(scenario.world_for_run()) & fingers
    # The planners' yes-or-no check skips the same pairs.
    touching_links = (
        "[" + ", ".join(sorted(touching(load_scenario(PUSH).world_for_run()))) + "]"
    )
    everything = load_scenario(
        PUSH, overrides={"world.objects.box.allow_contact": touching_links}
    )
    assert everything.world_for_run().is_free(q)
    assert not load_scenario(PUSH).world_for_run().is_free(q)


def test_an_unknown_link_is_a_located_error() -> None:
    with pytest.raises(ScenarioError, match="allow_contact: no link 'panda_hnad'"):
        load_scenario(
            PUSH, overrides={"world.objects.box.allow_contact": "[panda_hnad]"}
        )
