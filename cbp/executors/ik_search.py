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

import itertools
import math
from typing import TYPE_CHECKING

import numba
import numpy as np
import pinocchio as pin

from cbp.collision.world import CollisionWorld
from cbp.methods.settings import IkSearchSettings, Work
from cbp.robot import FloatArray, RobotModel
from cbp.run.budget import Budget

if TYPE_CHECKING:
    pass

__all__ = ["IkSearch", "check_work", "dls_step", "solve_pose"]

#: One start of a search: (seed, the joint held fixed or None).
_Start = tuple[FloatArray, int | None]
#: What a search is for: (goal, the world's environment, the configuration near).
_SearchKey = tuple[pin.SE3, object, FloatArray]


def check_work(world: CollisionWorld) -> Work:
    """The work one yes-or-no check of ``world`` is charged as.

    A check against an occupancy map costs an order of magnitude more than
    one against declared objects (:class:`~cbp.methods.settings.VirtualCosts`).
    """
    return "map_check" if world.against_map else "collision_check"


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
        self._rng = np.random.default_rng(0)
        self._goal: pin.SE3 | None = None
        self._solution: FloatArray | None = None
        # Searches by (goal, the world's environment, the configuration searched
        # near): the last one that tried every start and found nothing, and the
        # one under way with the starts it has left.
        self._failed: _SearchKey | None = None
        self._pending: tuple[_SearchKey, list[_Start]] | None = None

    def solution_for(
        self, goal: pin.SE3, q_near: FloatArray, budget: Budget
    ) -> FloatArray | None:
        """:meth:`solve`, spread over calls and remembered while the goal stays.

        The executors ask every command period. A search that ``budget`` cuts
        short goes on from where it stopped at the next call while the goal and
        ``q_near`` stay (otherwise it starts again); each start is tried
        against the world of its own call. A new map snapshot does not start
        it again: with the cameras one comes nearly every period, and a search
        begun anew in each would never try its later starts nor end. A
        solution is kept while the goal stays the same; a search that tried
        every start and found none is not repeated until the goal, the world
        (a new map snapshot, a moved object) or the arm's configuration (by
        1 mrad in any joint) changes: it would find none again.
        """
        if self._goal is not None and goal.isApprox(self._goal, 1e-9):
            return self._solution
        self._goal = self._solution = None
        if self._failed is not None and self._same(self._failed, goal, q_near):
            return None
        pending = self._pending
        if pending is None or not self._same(pending[0], goal, q_near, world=False):
            key = (goal, None, q_near.copy())
            pending = self._pending = (key, self.attempts(q_near))
        starts = pending[1]
        while starts and not budget.spent():
            seed, fixed = starts.pop(0)
            q = self.attempt(goal, seed, fixed, budget)
            if q is not None:
                self._pending = None
                self._goal, self._solution = goal, q
                return q
        if not starts:  # every start tried; the last ones against this world
            self._pending = None
            self._failed = (goal, self._environment(), pending[0][2])
        return None

    def _environment(self) -> object:
        return None if self.world is None else self.world.environment

    def _same(
        self, key: _SearchKey, goal: pin.SE3, q: FloatArray, world: bool = True
    ) -> bool:
        """``key``'s search is this one: same goal and start (and ``world``: world)."""
        their_goal, environment, their_q = key
        return (
            goal.isApprox(their_goal, 1e-9)
            and (not world or environment is self._environment())
            and float(np.max(np.abs(q - their_q))) < 1e-3
        )

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
        first, and held at each; then ``random_starts`` starts drawn within the
        limits let every joint move (from the search's own seeded stream).
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
        for _ in range(s.random_starts):
            out.append((self._rng.uniform(self._lower, self._upper), None))
        return out

    def attempt(
        self, goal: pin.SE3, seed: FloatArray, fixed: int | None, budget: Budget
    ) -> FloatArray | None:
        """One start of :meth:`attempts`: a collision-free solution, or None."""
        q = self._solve_from(goal, seed, fixed, budget)
        if q is not None and self.collision_free(q, budget):
            return q
        return None

    def motion_free(
        self, a: FloatArray, b: FloatArray, budget: Budget | None = None
    ) -> bool:
        """Whether the joint-space line from ``a`` to ``b`` is free all along.

        ``b`` and the configurations between, close enough that the unpadded
        links keep half the padding between checks
        (:meth:`~cbp.collision.world.CollisionWorld.motion_free`), each charged
        to ``budget``; ``a`` is taken as checked.
        """
        if self.world is None:
            return True
        return self.world.motion_free(a, b, lambda q: self.collision_free(q, budget))

    def path_free(self, points: FloatArray, budget: Budget | None = None) -> bool:
        """Whether every segment between consecutive ``points`` is free all along.

        :meth:`motion_free` for each, in order, up to the first that is not;
        the first point is taken as checked.
        """
        return all(
            self.motion_free(a, b, budget) for a, b in itertools.pairwise(points)
        )

    def motion_steps(self, a: FloatArray, b: FloatArray) -> int:
        """Segments to cut the line from ``a`` to ``b`` into, as :meth:`motion_free`."""
        world = self.world
        if world is None:
            return 1
        return world.sweep.segments(a, b, world.sweep_step)

    def collision_free(self, q: FloatArray, budget: Budget | None = None) -> bool:
        """No padded link penetrates an obstacle or another link.

        The check is charged to ``budget`` when one is given.
        """
        if self.world is None:
            return True
        if budget is not None:
            budget.charge(check_work(self.world))
        return self.world.is_free(q)

    def _solve_from(
        self, goal: pin.SE3, q: FloatArray, fixed: int | None, budget: Budget
    ) -> FloatArray | None:
        s = self.settings
        found, iterations = solve_pose(
            self.robot.model,
            self._data,
            self.frame_id,
            goal,
            q,
            (self._lower, self._upper),
            budget,
            iterations=s.max_iterations,
            tolerances=(s.position_tolerance, s.rotation_tolerance),
            damping=DAMPING,
            held=fixed,
            stall=s.stall_iterations,
        )
        self.solves += iterations
        return found


def solve_pose(
    model: pin.Model,
    data: pin.Data,
    frame: int,
    goal: pin.SE3,
    q: FloatArray,
    limits: tuple[FloatArray, FloatArray],
    budget: Budget,
    *,
    iterations: int,
    tolerances: tuple[float, float],
    damping: float,
    held: int | None = None,
    stall: int = 0,
) -> tuple[FloatArray | None, int]:
    """Damped least squares from ``q`` until ``frame`` is at ``goal``.

    Args:
        model: the robot's model.
        data: its data (the kinematics are computed in it).
        frame: the frame placed at the goal.
        goal: the frame's pose sought.
        q: the configuration to start from (not changed).
        limits: the lower and upper joint limits the steps keep within.
        budget: each iteration is charged to it.
        iterations: the most iterations.
        tolerances: the position [m] and rotation [rad] errors that count as
            there.
        damping: added to J J^T's diagonal.
        held: a velocity coordinate kept still (None: every joint moves).
        stall: give up once the error has not fallen by a thousandth over
            this many iterations (0: never).

    Returns:
        The configuration (None: not reached), and the iterations taken.
    """
    lower, upper = limits
    position_tolerance, rotation_tolerance = tolerances
    # Joints whose configuration is their angle (revolute, prismatic): the
    # step is added and clipped in the compiled pass; else pinocchio
    # integrates it.
    vector = model.nq == model.nv
    q, step = q.copy(), np.empty(model.nv)
    fixed = -1 if held is None else held
    errors = np.empty(iterations)  # position + rotation error norms
    for k in range(iterations):
        budget.charge("ik_iteration")
        pin.framesForwardKinematics(model, data, q)
        error = goal.actInv(data.oMf[frame])
        err = pin.log6(error).vector
        position = math.hypot(err[0], err[1], err[2])
        rotation = math.hypot(err[3], err[4], err[5])
        if position < position_tolerance and rotation < rotation_tolerance:
            return q, k + 1
        errors[k] = position + rotation
        if stall and k >= stall and errors[k] > 0.999 * errors[k - stall]:
            return None, k + 1  # stalled (a joint limit, a singularity)
        J = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL)
        dls_step(
            err, J, pin.Jlog6(error), fixed, damping, q, lower, upper, vector, step
        )
        if vector:
            q, step = step, q
        else:
            q = np.clip(pin.integrate(model, q, step), lower, upper)
    return None, iterations


#: Damping of the least-squares steps (added to J J^T's diagonal).
DAMPING = 1e-6


@numba.njit(cache=True, nogil=True)
def dls_step(
    err: FloatArray,
    J: FloatArray,
    Jlog: FloatArray,
    held: int,
    damping: float,
    q: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    vector: bool,
    out: FloatArray,
) -> None:  # pragma: no cover - compiled
    """One damped least-squares step on the pose error ``err`` (log6), into ``out``.

    The step is -Jt^T (Jt Jt^T + damping I)^-1 err with Jt = ``Jlog`` ``J``
    (the frame's local Jacobian through the log's), joint ``held`` (>= 0)
    kept still; J Jt^T is solved by its Cholesky factors. ``vector``: ``out``
    is ``q`` plus the step, within the limits; else the step alone.
    """
    n = J.shape[1]
    Jt = np.zeros((6, n))
    for i in range(6):
        for k in range(6):
            a = Jlog[i, k]
            if a != 0.0:
                for j in range(n):
                    Jt[i, j] += a * J[k, j]
    if held >= 0:
        for i in range(6):
            Jt[i, held] = 0.0
    L = np.zeros((6, 6))
    for i in range(6):
        for k in range(i + 1):
            s = damping if i == k else 0.0
            for j in range(n):
                s += Jt[i, j] * Jt[k, j]
            for j in range(k):
                s -= L[i, j] * L[k, j]
            L[i, k] = math.sqrt(s) if i == k else s / L[k, k]
    x = np.empty(6)
    for i in range(6):  # L y = err
        s = err[i]
        for j in range(i):
            s -= L[i, j] * x[j]
        x[i] = s / L[i, i]
    for i in range(5, -1, -1):  # L^T x = y
        s = x[i]
        for j in range(i + 1, 6):
            s -= L[j, i] * x[j]
        x[i] = s / L[i, i]
    for j in range(n):
        s = 0.0
        for i in range(6):
            s -= Jt[i, j] * x[i]
        out[j] = min(max(q[j] + s, lower[j]), upper[j]) if vector else s


dls_step(  # compiled (or loaded from numba's cache) on import
    np.zeros(6),
    np.eye(6, 1),
    np.eye(6),
    -1,
    DAMPING,
    np.zeros(1),
    -np.ones(1),
    np.ones(1),
    True,
    np.zeros(1),
)
