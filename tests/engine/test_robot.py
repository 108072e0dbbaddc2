"""Robot model: kinematics against PyBullet, names, nq != nv."""

from __future__ import annotations

import numpy as np
import pybullet as pb
import pytest

from cbp.errors import FrameNotFoundError, JointNotFoundError, RobotNotFoundError
from cbp.robot import RobotModel
from cbp.state import RobotState
from cbp.testing import sample_configurations


@pytest.fixture(scope="module")
def bullet(robots):
    """The same URDF in PyBullet DIRECT mode, fingers at their locked value."""
    robot = robots["panda"]
    client = pb.connect(pb.DIRECT)
    body = pb.loadURDF(str(robot.urdf_path), useFixedBase=True, physicsClientId=client)
    joints = {
        pb.getJointInfo(body, i, physicsClientId=client)[1].decode(): i
        for i in range(pb.getNumJoints(body, physicsClientId=client))
    }
    links = {
        pb.getJointInfo(body, i, physicsClientId=client)[12].decode(): i
        for i in range(pb.getNumJoints(body, physicsClientId=client))
    }
    yield client, body, joints, links
    pb.disconnect(client)


def test_kinematics_match_pybullet(robots, bullet, rng) -> None:
    """Link positions, orientations and Jacobians agree with PyBullet's."""
    robot = robots["panda"]
    client, body, joints, links = bullet
    movable = [
        i
        for i in range(pb.getNumJoints(body, physicsClientId=client))
        if pb.getJointInfo(body, i, physicsClientId=client)[2] != pb.JOINT_FIXED
    ]
    for q in sample_configurations(robot, rng, n=5):
        full = {name: value for name, value in zip(robot.joint_names, q, strict=True)}
        full.update(robot.description.locked_joints)
        for name, value in full.items():
            pb.resetJointState(body, joints[name], value, physicsClientId=client)
        state = RobotState(robot, q)
        for link in ("panda_link4", "panda_hand"):
            fid = robot.frame_id(link)
            ls = pb.getLinkState(
                body, links[link], computeForwardKinematics=True, physicsClientId=client
            )
            np.testing.assert_allclose(state.frame_position(fid), ls[4], atol=1e-6)
            R = np.array(pb.getMatrixFromQuaternion(ls[5])).reshape(3, 3)
            np.testing.assert_allclose(state.frame_rotation(fid), R, atol=1e-6)
            positions = [
                full[pb.getJointInfo(body, i, physicsClientId=client)[1].decode()]
                for i in movable
            ]
            zeros = [0.0] * len(movable)
            lin, ang = pb.calculateJacobian(
                body,
                links[link],
                [0, 0, 0],
                positions,
                zeros,
                zeros,
                physicsClientId=client,
            )
            arm = [movable.index(joints[n]) for n in robot.joint_names]
            J = state.frame_jacobian(fid)
            np.testing.assert_allclose(J[:3], np.array(lin)[:, arm], atol=1e-6)
            np.testing.assert_allclose(J[3:], np.array(ang)[:, arm], atol=1e-6)


def test_point_jacobian_matches_a_point_offset(robots, rng) -> None:
    """The Jacobian of a point fixed on a link matches finite differences."""
    robot = robots["panda_floating"]
    fid = robot.frame_id("panda_link5")
    q = sample_configurations(robot, rng, n=1)[0]
    state = RobotState(robot, q)
    offset_local = np.array([0.03, -0.02, 0.05])
    point = state.frame_placement(fid).act(offset_local)
    J = state.point_jacobian(fid, point)
    eps = 1e-6
    for i in range(robot.nv):
        step = np.zeros(robot.nv)
        step[i] = eps
        plus = (
            RobotState(robot, robot.integrate(q, step))
            .frame_placement(fid)
            .act(offset_local)
        )
        minus = (
            RobotState(robot, robot.integrate(q, -step))
            .frame_placement(fid)
            .act(offset_local)
        )
        np.testing.assert_allclose(J[:, i], (plus - minus) / (2 * eps), atol=1e-6)


def test_bases_change_the_tangent_size(robots) -> None:
    """Planar adds (x, y, cos, sin) / 3 dofs; floating adds 7 / 6."""
    assert (robots["panda"].nq, robots["panda"].nv) == (7, 7)
    assert (robots["panda_planar"].nq, robots["panda_planar"].nv) == (11, 10)
    assert (robots["panda_floating"].nq, robots["panda_floating"].nv) == (14, 13)


def test_names_suggest_close_matches(robots) -> None:
    """Unknown frames, joints and robots list what is close."""
    robot = robots["panda"]
    with pytest.raises(
        FrameNotFoundError,
        match="no frame 'panda_hnd' in robot 'franka_panda'; close matches: panda_hand",
    ):
        robot.frame_id("panda_hnd")
    with pytest.raises(JointNotFoundError, match="close matches: panda_joint1"):
        robot.joint_id("panda_joint_1")
    with pytest.raises(RobotNotFoundError) as info:
        RobotModel.load("franka_pnda")
    assert str(info.value).startswith(
        "no robot 'franka_pnda': no folder 'franka_pnda' with a robot.yaml in "
    )
    assert "(shipped robots). Did you mean 'franka_panda'? Robots on the" in str(
        info.value
    )
