# SPDX-License-Identifier: Apache-2.0
"""Collision-free inverse kinematics near a given configuration (CAT Sec. V-A).

The PR2's IK swept its redundant joint and solved the other six analytically.
Here the redundant joint is swept the same way, nearest values first, and the
other joints are solved numerically (damped least squares on the frame's pose
error, pinocchio); the first solution that is within the joint limits and free
of collisions (the scenario's collision world, padded links) is returned.
Starting from the current configuration and sweeping outward keeps the solution
close to it, so small goal changes give small joint changes.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from cbp.collision.world import CollisionWorld
from cbp.executors.clock import Budget
from cbp.executors.settings import IkSearchSettings
from cbp.robot import FloatArray, RobotModel

__all__ = ["IkSearch"]


class IkSearch:
    """Finds collision-free joint angles for a frame pose, near a configuration.

    Args:
        robot: the robot (fixed base, scalar joints).
        frame: the frame placed at the goal.
        world: collision world for the checks (None: no collision checks).
        settings: sweep, iterations, tolerances.
    """

    def __init__(
        self,
        robot: RobotModel,
        frame: str,
        world: CollisionWorld | None,
        settings: IkSearchSettings,
    ) -> None:
        """Resolve the frame and the swept joint."""
        self.robot = robot
        self.settings = settings
        self.world = world
        self.frame_id = robot.frame_id(frame)
        self._data = robot.model.createData()
        name = settings.redundant_joint or robot.joint_names[min(2, robot.nv - 1)]
        self.redundant = robot.joint_v_slice(name).start
        margin = settings.limit_margin
        self._lower = robot.lower_limits + margin
        self._upper = robot.upper_limits - margin
        self.solves = 0
        self._goal: pin.SE3 | None = None
        self._solution: FloatArray | None = None

    def solution_for(
        self, goal: pin.SE3, q_near: FloatArray, budget: Budget
    ) -> FloatArray | None:
        """:meth:`solve`, remembered while the goal stays the same.

        The executors ask every command period; the search runs again only
        for a new goal, or after a failure (from where the arm is then).
        """
        if self._goal is None or not goal.isApprox(self._goal, 1e-9):
            self._goal = goal
            self._solution = self.solve(goal, q_near, budget)
            if self._solution is None:
                self._goal = None
        return self._solution

    def solve(
        self, goal: pin.SE3, q_near: FloatArray, budget: Budget
    ) -> FloatArray | None:
        """A collision-free solution near ``q_near``, or None once ``budget`` is spent.

        Each iteration and collision check is charged to ``budget``.
        """
        for seed, fixed in self.attempts(q_near):
            if budget.spent():
                return None
            q = self.attempt(goal, seed, fixed, budget)
            if q is not None:
                return q
        return None

    def attempts(self, q_near: FloatArray) -> list[tuple[FloatArray, int | None]]:
        """The starts :meth:`solve` tries, in order: (seed, joint held fixed).

        The nearest solution first lets every joint move; then the redundant
        joint is swept outward from its value in ``q_near``, nearest values
        first, and held at each.
        """
        s = self.settings
        j = self.redundant
        current = float(q_near[j])
        values = [current]
        lo, hi = self._lower[j], self._upper[j]
        k = 1
        while current - k * s.sweep_step >= lo or current + k * s.sweep_step <= hi:
            for v in (current + k * s.sweep_step, current - k * s.sweep_step):
                if lo <= v <= hi:
                    values.append(v)
            k += 1
        out: list[tuple[FloatArray, int | None]] = []
        for i, value in enumerate(values):
            seed = np.clip(q_near, self._lower, self._upper)
            seed[j] = value
            out.append((seed, None if i == 0 else j))
        return out

    def attempt(
        self, goal: pin.SE3, seed: FloatArray, fixed: int | None, budget: Budget
    ) -> FloatArray | None:
        """One start of :meth:`attempts`: a collision-free solution, or None."""
        q = self._solve_from(goal, seed, fixed, budget)
        if q is not None and self.collision_free(q, budget):
            return q
        return None

    def collision_free(self, q: FloatArray, budget: Budget | None = None) -> bool:
        """No padded link penetrates an obstacle or another link.

        The check is charged to ``budget`` when one is given.
        """
        if self.world is None:
            return True
        if budget is not None:
            budget.charge("collision_check")
        return self.world.is_free(q)

    def _solve_from(
        self, goal: pin.SE3, q: FloatArray, fixed: int | None, budget: Budget
    ) -> FloatArray | None:
        s = self.settings
        model, data = self.robot.model, self._data
        q = q.copy()
        damping = 1e-6
        for _ in range(s.max_iterations):
            self.solves += 1
            budget.charge("ik_iteration")
            pin.framesForwardKinematics(model, data, q)
            M = data.oMf[self.frame_id]
            error = goal.actInv(M)
            err = pin.log6(error).vector
            if (
                np.linalg.norm(err[:3]) < s.position_tolerance
                and np.linalg.norm(err[3:]) < s.rotation_tolerance
            ):
                return q
            J = pin.computeFrameJacobian(model, data, q, self.frame_id, pin.LOCAL)
            J = pin.Jlog6(error).dot(J)
            if fixed is not None:
                J[:, fixed] = 0.0
            JJt = J.dot(J.T)
            JJt[np.diag_indices(6)] += damping
            dq = -J.T.dot(np.linalg.solve(JJt, err))
            q = np.clip(pin.integrate(model, q, dq), self._lower, self._upper)
        return None
