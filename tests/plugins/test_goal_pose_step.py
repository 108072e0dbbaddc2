# SPDX-License-Identifier: Apache-2.0
"""goal_pose's step limit: how far one step may ask the frame to move."""

from __future__ import annotations

import numpy as np
import pytest

from cbp.plugins.tasks.goal_pose_task import GoalPoseParams, GoalPoseTask


@pytest.mark.parametrize("clip", ["uniform", "independent"])
def test_a_limited_step_keeps_its_direction_within_both_limits(
    clip: str, robots, rng
) -> None:
    """Each part within its limit, along the step asked for; small steps as asked."""
    task = GoalPoseTask(
        GoalPoseParams(max_step_translation=0.02, max_step_rotation=0.1, clip=clip),
        robots["panda"],
    )
    for _ in range(200):
        desired = rng.normal(size=6) * rng.choice([1e-3, 1e-2, 0.1, 1.0])
        limited = task.limit_step(desired)
        t, r = np.linalg.norm(desired[:3]), np.linalg.norm(desired[3:])
        st = np.linalg.norm(limited[:3]) / t
        sr = np.linalg.norm(limited[3:]) / r
        assert np.linalg.norm(limited[:3]) <= 0.02 * (1 + 1e-12)
        assert np.linalg.norm(limited[3:]) <= 0.1 * (1 + 1e-12)
        np.testing.assert_allclose(limited[:3], st * desired[:3], rtol=1e-12)
        np.testing.assert_allclose(limited[3:], sr * desired[3:], rtol=1e-12)
        if clip == "uniform":
            assert st == pytest.approx(sr, rel=1e-12)
            expected = min(1.0, 0.02 / t, 0.1 / r)
        else:
            assert sr == pytest.approx(min(1.0, 0.1 / r), rel=1e-12)
            expected = min(1.0, 0.02 / t)
        assert st == pytest.approx(expected, rel=1e-12)
        if t <= 0.02 and r <= 0.1:
            np.testing.assert_array_equal(limited, desired)
