# SPDX-License-Identifier: Apache-2.0
"""The simulated robot: 1 kHz physics, a joint trajectory follower, torque control.

:class:`Simulation` steps a physics engine (:mod:`cbp.sim.physics`: PyBullet
by default, or MuJoCo) at a fixed rate (1 kHz by default) with the robot in
torque mode. Each physics step runs one low-level controller:

* **trajectory following** (:meth:`Simulation.follow`): the commanded trajectory's
  position, velocity and acceleration at the step's time, through a joint
  impedance (computed-torque PD) law
  ``tau = M(q) (a_d + Kp (q_d - q) + Kd (v_d - v)) + h(q, v)`` with pinocchio's
  RNEA on the same URDF, clipped to the joints' effort limits; a new trajectory
  can be spliced in at any time (CAT Sec. III and IV-D);
* **torque control** (:meth:`Simulation.set_torque_controller`): a user function
  of (t, q, v) returning joint torques, called every physics step (the JT
  executor).

Every physics step also measures contact between the robot and the scene: the
sum of the engine's contact normal forces and the deepest penetration, and the
part of the force on the hand (the robot's ``wrist_link`` and the links beyond
it), which is what a wrist force sensor would read from contacts.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
import pinocchio as pin

from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings
from cbp.sim.bullet_access import PybulletAccess
from cbp.sim.physics import Physics, make_physics
from cbp.sim.recorder import Recorder
from cbp.sim.trajectory import TRAJECTORY_HISTORY, JointTrajectory

__all__ = ["ContactSample", "Simulation", "TorqueController"]

log = logging.getLogger(__name__)

#: ``(t, q, v) -> tau``: joint torques (nv) from time [s], positions and velocities.
TorqueController = Callable[[float, FloatArray, FloatArray], FloatArray]


@dataclass
class ContactSample:
    """What the contact monitor measured over the recorded interval.

    Attributes:
        force: largest sum of normal forces between the robot and the scene [N].
        penetration: deepest penetration between robot and scene [m] (>= 0).
        wrist_force: sum of normal forces on the hand (``wrist_link`` and beyond) [N].
    """

    force: float = 0.0
    penetration: float = 0.0
    wrist_force: float = 0.0


class Simulation(PybulletAccess):
    """The simulated robot among the scenario's objects, on a physics engine.

    The controller is this class's; the engine (:class:`cbp.sim.physics.Physics`)
    is a part, PyBullet by default.

    Args:
        robot: the robot model (the controlled joints are its joints).
        objects: the scene's objects (the same declarations as the collision
            world's).
        q0: initial configuration.
        settings: rate, gains, recording.
        folder: where mesh files of objects are resolved from.
        gui: open the engine's window (PyBullet's).
        simulator: the engine, by name (:data:`cbp.sim.physics.SIMULATORS`).

    Attributes:
        physics: the engine.
        t: simulated time [s].
        steps: physics steps taken.
    """

    def __init__(
        self,
        robot: RobotModel,
        objects: list[ObjectSpec],
        q0: FloatArray,
        settings: SimulationSettings | None = None,
        folder: Path | None = None,
        gui: bool = False,
        *,
        simulator: str = "pybullet",
    ) -> None:
        """Build the engine's scene with the robot at ``q0``, torque-driven."""
        if robot.nq != robot.nv:
            raise NotImplementedError(
                "Simulation drives fixed-base robots with scalar joints; "
                f"'{robot.name}' has nq={robot.nq}, nv={robot.nv}"
            )
        self.robot = robot
        self.settings = settings or SimulationSettings()
        self.simulator = simulator
        self.dt = 1.0 / self.settings.rate_hz
        self.physics: Physics = make_physics(
            simulator, robot, objects, q0, self.settings, folder, gui
        )
        self._effort = np.asarray(self.physics.effort, dtype=float).copy()
        self._effort[self._effort <= 0] = np.inf
        self._data = robot.model.createData()
        self.t = 0.0
        self.steps = 0
        #: The sum of the normal forces of the last physics step [N].
        self.contact_force = 0.0
        self._trajectory = JointTrajectory.hold(0.0, np.asarray(q0, dtype=float))
        self._torque: TorqueController | None = None
        n = robot.nq
        # t, q, v, q_cmd, contact force, penetration, wrist force
        self._record = Recorder(1 + 3 * n + 3)
        self._q, self._v = self.physics.state()
        self._interval = ContactSample()

    # ------------------------------------------------------------------ control

    def follow(self, trajectory: JointTrajectory) -> None:
        """Track ``trajectory`` with the joint impedance law from now on.

        Points older than :data:`~cbp.sim.trajectory.TRAJECTORY_HISTORY` are
        dropped (executors look back along the way the arm came, not further):
        the trajectory stays bounded over a long run.
        """
        self._trajectory = trajectory.since(self.t - TRAJECTORY_HISTORY)
        self._torque = None

    @property
    def trajectory(self) -> JointTrajectory:
        """The trajectory being followed."""
        return self._trajectory

    def set_torque_controller(self, controller: TorqueController) -> None:
        """Drive the joints with ``controller`` every physics step from now on."""
        self._torque = controller

    def gravity(self, q: FloatArray) -> FloatArray:
        """Gravity torques at ``q`` (pinocchio, same URDF as the simulated arm)."""
        return np.asarray(
            pin.computeGeneralizedGravity(self.robot.model, self._data, q)
        ).copy()

    # ------------------------------------------------------------------ stepping

    def run_until(self, t_end: float) -> None:
        """Step the physics until simulated time ``t_end`` [s]."""
        while self.t + 0.5 * self.dt < t_end:
            self.step()

    def step(self) -> None:
        """One physics step: control, simulate, measure, maybe record."""
        q, v = self._q, self._v
        if self._torque is not None:
            tau = np.asarray(self._torque(self.t, q, v), dtype=float)
            q_cmd = q
        else:
            q_cmd, v_cmd, a_cmd = self._trajectory.sample(self.t)
            s = self.settings
            a = _impedance(a_cmd, q_cmd, q, v_cmd, v, s.stiffness, s.damping)
            tau = pin.rnea(self.robot.model, self._data, q, v, a)
        physics = self.physics
        physics.apply(_clipped(tau, self._effort))
        physics.step(self.t + self.dt)
        self.t = (self.steps + 1) * self.dt
        self.steps += 1
        self._q, self._v = physics.state()
        force, depth, wrist = physics.contact()
        self.contact_force = force
        interval = self._interval
        interval.force = max(interval.force, force)
        interval.penetration = max(interval.penetration, depth)
        interval.wrist_force = max(interval.wrist_force, wrist)
        if self.steps % self.settings.record_every == 0:
            row = self._record.row()
            n = self.robot.nq
            row[0] = self.t
            row[1 : 1 + n] = self._q
            row[1 + n : 1 + 2 * n] = self._v
            row[1 + 2 * n : 1 + 3 * n] = q_cmd
            row[1 + 3 * n :] = (
                interval.force,
                interval.penetration,
                interval.wrist_force,
            )
            self._interval = ContactSample()

    @property
    def q(self) -> FloatArray:
        """Measured joint positions."""
        return self._q

    @property
    def v(self) -> FloatArray:
        """Measured joint velocities."""
        return self._v

    def recording(self) -> dict[str, FloatArray]:
        """Recorded samples: t, q, v, q_cmd, contact force, penetration, wrist force.

        Force, penetration and wrist force are the largest values over the
        physics steps since the previous sample.
        """
        rows = self._record.array()
        n = self.robot.nq
        return {
            "t": rows[:, 0].copy(),
            "q": rows[:, 1 : 1 + n].copy(),
            "v": rows[:, 1 + n : 1 + 2 * n].copy(),
            "q_cmd": rows[:, 1 + 2 * n : 1 + 3 * n].copy(),
            "contact_force": rows[:, 1 + 3 * n].copy(),
            "penetration": rows[:, 2 + 3 * n].copy(),
            "wrist_force": rows[:, 3 + 3 * n].copy(),
        }

    def close(self) -> None:
        """Release the engine; delete the recording's spool file."""
        self.physics.close()
        self._record.close()

    def __enter__(self) -> Simulation:
        """Use as a context manager."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Release the engine."""
        self.close()


@numba.njit(cache=True, nogil=True)
def _impedance(
    a_cmd: FloatArray,
    q_cmd: FloatArray,
    q: FloatArray,
    v_cmd: FloatArray,
    v: FloatArray,
    stiffness: float,
    damping: float,
) -> FloatArray:
    """The commanded acceleration with the PD terms, a + Kp (q_d - q) + Kd (v_d - v).

    Joint by joint, in the order numpy took the operations before this was
    compiled: the same numbers.
    """
    a = np.empty(a_cmd.size)
    for j in range(a.size):
        a[j] = a_cmd[j] + stiffness * (q_cmd[j] - q[j]) + damping * (v_cmd[j] - v[j])
    return a


@numba.njit(cache=True, nogil=True)
def _clipped(tau: FloatArray, effort: FloatArray) -> list[float]:
    """``tau`` clipped to [-effort, effort] (as numpy's clip; NaN stays NaN), a list."""
    out = []
    for j in range(tau.size):
        x, bound = tau[j], effort[j]
        out.append(-bound if x < -bound else (bound if x > bound else x))
    return out


# Compiled (or loaded from numba's cache) on import, not in a run's first period.
_ZERO = np.zeros(1)
_clipped(_impedance(_ZERO, _ZERO, _ZERO, _ZERO, _ZERO, 1.0, 1.0), np.ones(1))
