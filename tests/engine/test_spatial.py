"""Goal poses are checked before they reach a plugin: shape, finiteness, rotation."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from cbp.errors import InvalidTargetError
from cbp.spatial import checked_se3, cross3

R = pin.rpy.rpyToMatrix(0.3, -0.2, 1.0)
P = np.array([0.4, 0.1, 0.5])


def test_a_rotation_is_accepted_within_numerical_noise() -> None:
    assert np.allclose(checked_se3(P, R).rotation, R)
    # Scaled by 1 + 4e-6: R^T R is 8e-6 off on its diagonal, as a rotation
    # rebuilt from a quaternion printed to six digits can be.
    checked_se3(P, R * (1.0 + 4e-6))


@pytest.mark.parametrize(
    ("position", "rotation", "message"),
    [
        (P, R * 1.001, "not a rotation matrix"),
        (P, -R, "not a rotation matrix"),  # det -1: a reflection
        (P, R + 1e-4 * np.triu(np.ones((3, 3)), 1), "not a rotation matrix"),
        (np.array([0.4, np.nan, 0.5]), R, "not finite"),
        (P, np.where(np.eye(3) > 0, np.inf, R), "not finite"),
        (P[:2], R, "shape"),
        (P, R[:2], "shape"),
    ],
)
def test_bad_goals_are_refused_with_the_reason(position, rotation, message) -> None:
    with pytest.raises(InvalidTargetError, match=message):
        checked_se3(position, rotation, "goal")


def test_cross3_is_the_cross_product(rng) -> None:
    for _ in range(20):
        a, b = rng.normal(size=3), rng.normal(size=3)
        np.testing.assert_allclose(cross3(a, b), np.cross(a, b), atol=1e-15)
