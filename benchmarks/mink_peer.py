# SPDX-License-Identifier: Apache-2.0
"""mink on MuJoCo: a peer of the reaching step timed by ``cbp bench``.

mink (``solve_ik`` on a MuJoCo model) does the reaching task of pink's row in
``benchmarks/bench.py``: a frame task on ``panda_hand`` (position cost 1,
orientation cost 0.3), a posture task (cost 1e-2, toward the middle of the
joint ranges), the joint position limits (gain 0.5, pink's default; mink's is
0.95) and the URDF's joint velocity limits, solved by daqp through qpsolvers,
as pink's is.

The MuJoCo model is compiled from the robot's own URDF (MuJoCo reads URDF),
with its collision meshes, the base fixed (the URDF's root has no joint), the
bodies of fixed joints kept (so that ``panda_hand`` is a body mink can move)
and the locked joints of robot.yaml (the Panda's fingers) removed, their
bodies moved to where the joint holds them, as pinocchio's reduced model does.

mink and mujoco are bench extras: ``pip install -e ".[bench]"``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.metrics import REACH_POSITION, REACH_ROTATION
from cbp.robot import RobotModel

__all__ = ["MinkReach", "mujoco_model"]

#: Costs and gains of the reaching task, as in pink's row of ``bench.py``.
POSITION_COST = 1.0
ORIENTATION_COST = 0.3
POSTURE_COST = 1e-2
LIMIT_GAIN = 0.5


def mujoco_model(robot: RobotModel) -> Any:
    """Compile ``robot``'s URDF into a MuJoCo model with the same joints.

    Args:
        robot: a fixed-base robot loaded from a URDF, as the engine uses it.

    Returns:
        The ``mujoco.MjModel``: bodies of fixed joints kept, the locked joints
        (robot.yaml's ``locked_joints``) removed with their bodies held at the
        locked positions [m or rad], joints in ``robot.joint_names``' order.

    Raises:
        ConfigError: the robot has no URDF, a moving base, a locked joint that
            is neither prismatic nor revolute, or joints that differ from the
            engine's.
    """
    import mujoco

    where = f"robot {robot.name!r}"
    if robot.urdf_path is None:
        raise ConfigError("has no URDF for MuJoCo to compile", where)
    if robot.base != "fixed":
        raise ConfigError(
            f"has a {robot.base} base; the mink peer builds fixed bases only", where
        )
    spec = mujoco.MjSpec.from_file(str(robot.urdf_path))
    spec.compiler.fusestatic = False
    locked = robot.description.locked_joints if robot.description else {}
    _lock_joints(spec, locked, where)
    model = spec.compile()
    names = [model.joint(j).name for j in range(model.njnt)]
    if names != robot.joint_names:
        raise ConfigError(
            f"MuJoCo's joints {names} differ from the engine's {robot.joint_names}",
            where,
        )
    return model


def _lock_joints(spec: Any, locked: Mapping[str, float], where: str) -> None:
    """Remove ``locked`` joints from ``spec``, moving their bodies to the values.

    A joint's body is moved in its parent's frame by the joint's motion at the
    locked value [m or rad], about or along the joint's axis through its anchor;
    equality constraints naming the joint (URDF mimic joints) go with it.
    """
    import mujoco

    for name, value in locked.items():
        joint = spec.joint(name)
        if joint is None:
            raise ConfigError(f"locked joint {name!r} is not in the URDF", where)
        body = joint.parent
        rotation = np.empty(9)
        mujoco.mju_quat2Mat(rotation, body.quat)
        rotation = rotation.reshape(3, 3)
        axis = np.asarray(joint.axis, dtype=float)
        axis /= np.linalg.norm(axis)
        if joint.type == mujoco.mjtJoint.mjJNT_SLIDE:
            body.pos = np.asarray(body.pos) + rotation @ (value * axis)
        elif joint.type == mujoco.mjtJoint.mjJNT_HINGE:
            turn = pin.exp3(value * axis)
            anchor = np.asarray(joint.pos, dtype=float)
            body.pos = np.asarray(body.pos) + rotation @ (anchor - turn @ anchor)
            quat = pin.Quaternion(rotation @ turn)
            body.quat = [quat.w, quat.x, quat.y, quat.z]
        else:
            raise ConfigError(
                f"locked joint {name!r} is a {joint.type.name}; the mink peer "
                "locks slide and hinge joints only",
                where,
            )
        for equality in list(spec.equalities):
            if name in (equality.name1, equality.name2):
                spec.delete(equality)
        spec.delete(joint)


class MinkReach:
    """The reaching step on mink: frame and posture tasks, both limits, daqp.

    Attributes:
        configuration: mink's ``Configuration`` (MuJoCo model and data), moved
            by each :meth:`step`.
        frame: the frame task on the goal frame.
        goals: the goals as mink poses, in the order given.
    """

    def __init__(
        self, robot: RobotModel, q0: np.ndarray, goals: Sequence[pin.SE3], dt: float
    ) -> None:
        """Build the model, the tasks and the limits once.

        Args:
            robot: the engine's robot (its URDF, locked joints and limits).
            q0: start configuration [rad], in ``robot.joint_names``' order.
            goals: goal poses of ``robot.end_effector`` in the world frame.
            dt: step duration [s].
        """
        import mink

        model = mujoco_model(robot)
        self.dt = dt
        self.frame_name = robot.end_effector
        self.configuration = mink.Configuration(model, np.array(q0, dtype=float))
        self.frame = mink.FrameTask(
            self.frame_name,
            "body",
            position_cost=POSITION_COST,
            orientation_cost=ORIENTATION_COST,
        )
        posture = mink.PostureTask(model, cost=POSTURE_COST)
        posture.set_target(robot.middle())
        self.tasks = [self.frame, posture]
        velocities = dict(zip(robot.joint_names, robot.velocity_limits, strict=True))
        self.limits = [
            mink.ConfigurationLimit(model, gain=LIMIT_GAIN),
            mink.VelocityLimit(model, velocities),
        ]
        self.goals = [mink.SE3.from_matrix(goal.homogeneous) for goal in goals]

    def step(self, goal: int) -> np.ndarray:
        """One step toward ``goals[goal]``: solve, integrate; return v [rad/s]."""
        import mink

        self.frame.set_target(self.goals[goal])
        v: np.ndarray = mink.solve_ik(
            self.configuration, self.tasks, self.dt, "daqp", limits=self.limits
        )
        self.configuration.integrate_inplace(v, self.dt)
        return v

    def error(self, goal: int) -> tuple[float, float]:
        """Distance [m] and angle [rad] from the frame to ``goals[goal]``."""
        pose = self.configuration.get_transform_frame_to_world(self.frame_name, "body")
        target = self.goals[goal]
        turn = target.rotation().inverse() @ pose.rotation()
        distance = np.linalg.norm(pose.translation() - target.translation())
        return float(distance), float(np.linalg.norm(turn.log()))

    def reach(self, goal: int, steps: int) -> int | None:
        """Step toward ``goals[goal]`` until within cbp's reach tolerances.

        Returns:
            The steps taken, or None when ``steps`` did not reach within
            :data:`cbp.metrics.REACH_POSITION` [m] and
            :data:`~cbp.metrics.REACH_ROTATION` [rad].
        """
        for k in range(steps):
            distance, angle = self.error(goal)
            if distance <= REACH_POSITION and angle <= REACH_ROTATION:
                return k
            self.step(goal)
        return None

    def stepper(self, cycle: int) -> Callable[[int], object]:
        """Call ``i`` of a reach as the benchmarks time it.

        Each call steps from where the last one left the arm toward
        ``goals[(i // cycle) % len(goals)]`` and returns the velocity [rad/s].
        """
        count = len(self.goals)

        def step(i: int) -> object:
            return self.step((i // cycle) % count)

        return step
