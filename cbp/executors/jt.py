# SPDX-License-Identifier: Apache-2.0
"""The JT method: Jacobian-transpose torque control (CAT Sec. V-C, eqs. 6-8).

At every physics step (1 kHz) the hand's pose error to the latest goal (sampled
at the command rate) becomes a wrench through a Cartesian stiffness and damping,
capped in magnitude, and the joint torques are

    tau = J^T f + (I - J^+ J) k (q_d - q) + g(q) - D v

(eq. 6 pose tracking, eq. 7 null-space posture toward the initial posture,
gravity compensation and joint damping). No collision avoidance, as in the paper.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from cbp.driver import TorqueDriven
from cbp.errors import ConfigError
from cbp.methods.settings import JtSettings
from cbp.robot import FloatArray
from cbp.run.loop import run_ticks
from cbp.run.parts import RunParts, build_run
from cbp.scenario.runtime import Scenario
from cbp.sim.trajectory import JointTrajectory
from cbp.trace import Trace

__all__ = ["JacobianTransposeController", "run_jt"]


class JacobianTransposeController:
    """The torque law of eqs. 6-8, called by the simulator every physics step."""

    def __init__(self, scenario: Scenario, run: RunParts) -> None:
        """Resolve the frame; the posture target is the initial configuration."""
        self.settings = scenario.spec.method.settings(JtSettings)
        self.robot = scenario.robot
        self.run = run
        self.frame_id = scenario.robot.frame_id(run.ee_frame)
        self.posture = scenario.q0.copy()
        self._data = scenario.robot.model.createData()
        self._eye = np.eye(scenario.robot.nv)

    def __call__(self, t: float, q: FloatArray, v: FloatArray) -> FloatArray:
        """Joint torques at time ``t`` for positions ``q`` and velocities ``v``."""
        s = self.settings
        model, data = self.robot.model, self._data
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        J = pin.getFrameJacobian(
            model, data, self.frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        tau = np.asarray(pin.computeGeneralizedGravity(model, data, q)).copy()
        tau -= s.joint_damping * v
        goal = self.run.goal.goal(t)
        if goal is not None:
            M = data.oMf[self.frame_id]
            twist = J.dot(v)
            force = s.stiffness_translation * (goal.translation - M.translation)
            force -= s.damping_translation * twist[:3]
            moment = s.stiffness_rotation * pin.log3(goal.rotation.dot(M.rotation.T))
            moment -= s.damping_rotation * twist[3:]
            wrench = np.concatenate(
                [_cap(force, s.max_force), _cap(moment, s.max_torque)]
            )
            tau += J.T.dot(wrench)
        J_pinv = np.linalg.pinv(J, rcond=1e-3)
        tau += (self._eye - J_pinv.dot(J)).dot(
            s.nullspace_stiffness * (self.posture - q)
        )
        return tau


def _cap(vector: FloatArray, limit: float) -> FloatArray:
    norm = float(np.linalg.norm(vector))
    return vector * (limit / norm) if norm > limit else vector


class _Torques:
    """JT's ticks: the simulator runs the torque law in slices of a command period."""

    def __init__(self, run: RunParts) -> None:
        self.run = run

    def tick(self, t: float) -> None:
        """Simulate up to ``t``."""
        self.run.advance(t)

    def hold(self, t: float) -> None:
        """Hold where the robot is, under the joint impedance."""
        sim = self.run.arm
        sim.follow(JointTrajectory.hold(sim.t, sim.q.copy()))


#: JT's slices [s]: the goal is sampled at the command rate.
SLICE = 1.0 / 30.0


def run_jt(scenario: Scenario, gui: bool = False) -> Trace:
    """Run ``scenario`` with the JT method; return the trace."""
    run = build_run(scenario, method="jt", gui=gui)
    try:
        robot = run.arm.driver
        if not isinstance(robot, TorqueDriven):
            raise ConfigError(
                f"jt drives the joints by torque every physics step; "
                f"{type(robot).__name__} offers no torque interface",
                "method",
            )
        robot.set_torque_controller(JacobianTransposeController(run.scenario, run))
        # In slices of a command period, so that a failure is an event.
        ends = np.arange(1, math.ceil(run.duration / SLICE - 1e-9) + 1) * SLICE
        times = np.minimum(ends, run.duration)
        run_ticks(_Torques(run), times, run.log, run.faults, "torque control")
    finally:
        trace = run.finish()
    return trace
