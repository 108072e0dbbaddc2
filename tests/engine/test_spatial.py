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


def _rotations(rng, n):
    """Random rotations, and rotations by angles near 0 and near and at π."""
    for k in range(n):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = [
            rng.uniform(0.0, np.pi),
            rng.uniform(0.0, 1e-3),
            np.pi - rng.uniform(0.0, 2e-3),
            np.pi,
            0.0,
        ][k % 5]
        yield angle, pin.exp3(angle * axis)


def test_log3_inverts_the_exponential(rng) -> None:
    """log3 agrees with pinocchio's, and exp3 of it is the rotation, even near π."""
    from cbp.spatial import log3

    for angle, M in _rotations(rng, 2000):
        got_angle, *w = log3(M)
        w = np.array(w)
        assert got_angle == pytest.approx(angle, abs=1e-9)
        np.testing.assert_allclose(pin.exp3(w), M, atol=1e-12)
        if angle < np.pi - 1e-6:  # at π, w and -w are the same rotation
            np.testing.assert_allclose(w, pin.log3(M), atol=1e-10)


def test_pose_error_matches_pinocchio(robots, rng) -> None:
    """The compiled pose error: [p - p_g; log3(R R_g^T)], Jlog3 M^T on angular rows."""
    from cbp.spatial import pose_error_into
    from cbp.state import RobotState
    from cbp.testing import sample_configurations

    robot = robots["panda"]
    frame = robot.frame_id("panda_hand")
    goals = list(_rotations(rng, 50))
    for k, q in enumerate(sample_configurations(robot, rng, n=50)):
        state = RobotState(robot, q)
        placement = state.frame_placement(frame)
        # Goals whose rotation error is random, tiny or near π.
        R_goal = goals[k][1].T.dot(placement.rotation)
        p_goal = rng.uniform(-1.0, 1.0, 3)
        value, jacobian = np.empty(6), np.empty((6, robot.nv))
        J_frame = state.frame_jacobian(frame)
        pose_error_into(
            placement.rotation,
            placement.translation,
            np.array(R_goal).T,
            p_goal,
            J_frame,
            value,
            jacobian,
        )
        M = placement.rotation.dot(R_goal.T)
        np.testing.assert_allclose(
            value[:3], placement.translation - p_goal, atol=1e-15
        )
        if goals[k][0] < np.pi - 1e-6:
            np.testing.assert_allclose(value[3:], pin.log3(M), atol=1e-10)
            if goals[k][0] < np.pi - 1e-2:  # Jlog3 grows without bound toward π
                expected = pin.Jlog3(M).dot(M.T).dot(J_frame[3:])
                np.testing.assert_allclose(jacobian[3:], expected, atol=1e-9)
        np.testing.assert_array_equal(jacobian[:3], J_frame[:3])


def test_compiled_pose_check_accepts_what_checked_pose_accepts(rng) -> None:
    """checked_pose_into agrees with checked_pose on noisy, reflected and NaN poses."""
    from cbp.spatial import checked_pose, checked_pose_into

    translation, rotation_t = np.zeros(3), np.eye(3)
    agreed = {True: 0, False: 0}
    for k in range(400):
        rotation = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        # Noise on both sides of the tolerance (about 1e-5 on R^T R).
        rotation = rotation + 10.0 ** rng.uniform(-8, -4) * rng.normal(size=(3, 3))
        if k % 10 == 0:
            rotation = -rotation
        position = rng.normal(size=3)
        if k % 25 == 0:
            position[k % 3] = np.nan
        if k % 2:
            rotation = np.asfortranarray(rotation)  # as pinocchio's are
        try:
            checked_pose(position, rotation)
            expected = True
        except InvalidTargetError:
            expected = False
        before = rotation_t.copy()
        assert (
            checked_pose_into(position, rotation, translation, rotation_t) is expected
        )
        if expected:
            assert np.array_equal(translation, position)
            assert np.array_equal(rotation_t, rotation.T)
        else:
            assert np.array_equal(rotation_t, before)  # nothing written
        agreed[expected] += 1
    assert min(agreed.values()) > 50  # both kinds were tried


def test_goal_pose_keeps_its_goal_when_a_bad_one_is_set(robots) -> None:
    """A refused target leaves the goal as it was, whatever the input's type."""
    from cbp.plugins.tasks.goal_pose_task import GoalPoseParams, GoalPoseTask

    task = GoalPoseTask(GoalPoseParams(), robots["panda"], "goal")
    task.set_target(P, R)
    for position, rotation in [
        (P, R * 1.001),
        (np.array([0.4, np.nan, 0.5]), R),
        (P.tolist(), (-R).tolist()),
        (P[:2], R),
    ]:
        with pytest.raises(InvalidTargetError):
            task.set_target(position, rotation)
        assert np.array_equal(task.target.translation, P)
        assert np.allclose(task.target.rotation, R, atol=0.0, rtol=0.0)
    task.set_target((P + 1.0).tolist(), R.tolist())  # lists: the long way
    assert np.array_equal(task.target.translation, P + 1.0)
