"""The Jacobian checker catches wrong Jacobians and reports where."""

from __future__ import annotations

import numpy as np
import pytest

from cbp.errors import JacobianMismatchError
from cbp.plugin import FloatArray
from cbp.plugins.tasks.goal_pose_task import GoalPoseParams, GoalPoseTask
from cbp.plugins.tasks.posture_task import PostureParams, PostureTask
from cbp.state import RobotState
from cbp.testing import check_jacobian, sample_configurations


class _TransposedRotation(GoalPoseTask):
    """Goal pose with a classic bug: the rotation rows miss the log map's Jacobian."""

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        return np.array(state.frame_jacobian(self.frame_id))


class _SignFlip(PostureTask):
    def compute_jacobian(self, state: RobotState) -> FloatArray:
        return -super().compute_jacobian(state)


def test_wrong_rotation_jacobian_fails(robots, rng) -> None:
    """Using the frame Jacobian for log3 rows is caught, with the worst entries."""
    robot = robots["panda"]
    task = _TransposedRotation(GoalPoseParams(frame="panda_hand"), robot)
    task.set_target([0.4, 0.0, 0.5], np.diag([1.0, -1.0, -1.0]))
    q = sample_configurations(robot, rng, n=1)[0]
    with pytest.raises(
        JacobianMismatchError,
        match=r"transposed_rotation\): max \|analytic - numeric\|",
    ) as info:
        check_jacobian(task, robot, q)
    assert (
        "J[3," in str(info.value)
        or "J[4," in str(info.value)
        or "J[5," in str(info.value)
    )


def test_sign_error_fails_on_a_floating_base(robots, rng) -> None:
    """A sign error is caught on a robot where nq != nv."""
    robot = robots["panda_floating"]
    task = _SignFlip(PostureParams(), robot)
    q = sample_configurations(robot, rng, n=1)[0]
    with pytest.raises(JacobianMismatchError):
        check_jacobian(task, robot, q)


def test_wrong_shape_fails(robots) -> None:
    """A Jacobian of the wrong shape is reported as such."""
    robot = robots["panda"]

    class _Short(PostureTask):
        def compute_jacobian(self, state: RobotState) -> FloatArray:
            return super().compute_jacobian(state)[:, :3]

    with pytest.raises(
        JacobianMismatchError, match=r"shape \(7, 3\), expected \(7, 7\)"
    ):
        check_jacobian(_Short(PostureParams(), robot), robot, robot.home())


class _FalselyConstant(GoalPoseTask):
    """Claims a constant Jacobian the engine would compute only once."""

    constant_jacobian = True


def test_false_constant_jacobian_claim_fails(robots, rng) -> None:
    """A plugin declaring constant_jacobian whose Jacobian moves is caught."""
    robot = robots["panda"]
    task = _FalselyConstant(GoalPoseParams(frame="panda_hand"), robot)
    task.set_target([0.4, 0.0, 0.5], np.diag([1.0, -1.0, -1.0]))
    q = sample_configurations(robot, rng, n=1)[0]
    with pytest.raises(JacobianMismatchError, match="declares constant_jacobian"):
        check_jacobian(task, robot, q)


def test_joint_space_terms_declare_constant_jacobians(robots, rng) -> None:
    """Posture is constant on a fixed base (checked), not on a floating one."""
    q = sample_configurations(robots["panda"], rng, n=1)[0]
    fixed = PostureTask(PostureParams(), robots["panda"])
    assert fixed.constant_jacobian
    check_jacobian(fixed, robots["panda"], q)
    assert not PostureTask(PostureParams(), robots["panda_floating"]).constant_jacobian


class _StaleRow(PostureTask):
    """Writes its Jacobian in place but forgets the last row."""

    def linearize_into(self, state, value, jacobian) -> None:  # type: ignore[no-untyped-def]
        full = np.empty_like(jacobian)
        super().linearize_into(state, value, full)
        jacobian[:-1] = full[:-1]


class _OffByOne(PostureTask):
    """Its in-place value (what the engine reads) is not its compute_value."""

    def value_into(self, state: RobotState, value: FloatArray) -> None:
        super().value_into(state, value)
        value += 1.0


@pytest.mark.parametrize(
    ("task", "match"),
    [
        (_StaleRow, "linearize_into's Jacobian differs"),
        (_OffByOne, "value_into's value differs"),
    ],
)
def test_in_place_outputs_are_checked(robots, rng, task, match) -> None:
    """The engine's in-place calls must agree with compute_value/compute_jacobian."""
    robot = robots["panda"]
    plugin = task(PostureParams(), robot)
    q = sample_configurations(robot, rng, n=1)[0]
    with pytest.raises(JacobianMismatchError, match=match):
        check_jacobian(plugin, robot, q)
