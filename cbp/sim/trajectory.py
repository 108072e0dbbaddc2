# SPDX-License-Identifier: Apache-2.0
"""Joint trajectories: quintic splines between points, splicing, time scaling.

A :class:`JointTrajectory` is a list of points (time, position, velocity,
acceleration). Between two points the motion is the quintic polynomial that
matches all three at both ends, so a trajectory is continuous in position,
velocity and acceleration (CAT Sec. III: "quintic splines between joint
trajectory points"). After its last point it holds the last position.

:func:`time_parameterize` turns a path of configurations (the QP steps of one
command period) into a trajectory that starts with a given velocity, stays within
velocity and acceleration limits, and stops at the path's end (CAT Sec. IV-D-1:
every joint can stop by the end of the horizon, so no computed trajectory leads
into an inevitable collision state).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from cbp.robot import FloatArray

__all__ = [
    "JointTrajectory",
    "SpliceError",
    "braking_now",
    "stopping_trajectory",
    "time_parameterize",
]


#: How much of a followed trajectory's past is kept [s]: executors look back
#: along the way the arm came, not further (:meth:`JointTrajectory.since`).
TRAJECTORY_HISTORY = 1.0


class SpliceError(ValueError):
    """A trajectory cannot be spliced in: it is discontinuous or starts in the past."""


@dataclass(frozen=True)
class JointTrajectory:
    """Points of a joint trajectory; quintic between points, held after the last.

    Attributes:
        times: point times, strictly increasing (N,) [s].
        positions: (N, n) joint positions.
        velocities: (N, n) joint velocities.
        accelerations: (N, n) joint accelerations.
    """

    times: FloatArray
    positions: FloatArray
    velocities: FloatArray
    accelerations: FloatArray

    def __post_init__(self) -> None:
        """Shapes agree and times increase."""
        n = self.times.size
        if n == 0:
            raise ValueError("a trajectory needs at least one point")
        for name in ("positions", "velocities", "accelerations"):
            if getattr(self, name).shape != self.positions.shape or (
                self.positions.shape[0] != n
            ):
                raise ValueError(f"{name}: shape {getattr(self, name).shape}")
        if n > 1 and not np.all(np.diff(self.times) > 0):
            raise ValueError("trajectory times must increase strictly")

    @classmethod
    def hold(cls, t: float, q: FloatArray) -> JointTrajectory:
        """Stay at ``q`` from time ``t`` on."""
        q = np.asarray(q, dtype=float)
        zero = np.zeros((1, q.size))
        return cls(np.array([t]), q[None, :].copy(), zero, zero.copy())

    @property
    def start_time(self) -> float:
        """Time of the first point [s]."""
        return float(self.times[0])

    @property
    def end_time(self) -> float:
        """Time of the last point [s]: the robot is at rest from then on."""
        return float(self.times[-1])

    def __len__(self) -> int:
        """Number of points."""
        return int(self.times.size)

    def sample(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Position, velocity and acceleration at time ``t``.

        Before the first point: the first point's position, at rest; after the
        last: the last position, at rest.
        """
        return _sample(
            self.times, self.positions, self.velocities, self.accelerations, float(t)
        )

    def first_point_after(self, t: float) -> int | None:
        """Index of the first point scheduled strictly after ``t``, or None."""
        i = int(np.searchsorted(self.times, t, side="right"))
        return i if i < self.times.size else None

    def point(self, i: int) -> tuple[float, FloatArray, FloatArray, FloatArray]:
        """Time, position, velocity and acceleration of point ``i``."""
        return (
            float(self.times[i]),
            self.positions[i],
            self.velocities[i],
            self.accelerations[i],
        )

    def since(self, t: float) -> JointTrajectory:
        """This trajectory without the points before the segment containing ``t``.

        The same motion from ``t`` on; a trajectory followed for hours keeps a
        bounded number of points.
        """
        i = int(np.searchsorted(self.times, t, side="right")) - 1
        if i <= 0:
            return self
        return JointTrajectory(
            self.times[i:],
            self.positions[i:],
            self.velocities[i:],
            self.accelerations[i:],
        )

    def delayed(self, dt: float) -> JointTrajectory:
        """The same motion ``dt`` later (>= 0): held at the first point until then."""
        if dt < 0:
            raise ValueError(f"a trajectory is delayed by dt >= 0, got {dt}")
        if dt == 0:
            return self
        return JointTrajectory(
            self.times + dt, self.positions, self.velocities, self.accelerations
        )

    def splice(self, new: JointTrajectory, tolerance: float = 1e-9) -> JointTrajectory:
        """This trajectory up to ``new``'s first point, then ``new``.

        ``new`` must start on this trajectory: its first position and velocity
        equal this trajectory's at that time (within ``tolerance``), so the
        commanded motion stays continuous (CAT Sec. IV-D-2).

        Raises:
            SpliceError: ``new`` does not start on this trajectory.
        """
        t0 = new.start_time
        q, v, _ = self.sample(t0)
        gap = max(
            float(np.max(np.abs(q - new.positions[0]))),
            float(np.max(np.abs(v - new.velocities[0]))),
        )
        if gap > tolerance:
            raise SpliceError(
                f"the new trajectory does not start on the current one at t={t0:.4f} s "
                f"(largest position or velocity gap {gap:.3g})"
            )
        keep = self.times < t0 - 1e-12
        return JointTrajectory(
            np.concatenate([self.times[keep], new.times]),
            np.concatenate([self.positions[keep], new.positions]),
            np.concatenate([self.velocities[keep], new.velocities]),
            np.concatenate([self.accelerations[keep], new.accelerations]),
        )


def time_parameterize(
    path: FloatArray,
    t0: float,
    v0: FloatArray,
    a0: FloatArray,
    max_velocity: FloatArray,
    max_acceleration: FloatArray,
) -> JointTrajectory | None:
    r"""Time a path of configurations so that it starts at ``v0`` and stops at its end.

    The path's points are joined by straight segments; the speed along the path
    is the largest profile that respects, joint by joint, ``max_velocity`` at
    every point, ``max_acceleration`` on every segment and at every corner
    (where the direction changes), reaches zero at the
    last point (a forward-backward pass over :math:`\dot s^2`), and starts at the
    component of ``v0`` along the first segment. The first point keeps ``v0`` and
    ``a0`` exactly (continuity with the trajectory it is spliced into); the first
    segment is lengthened when needed so that the change from ``v0`` to the
    second point's velocity respects ``max_acceleration``.

    Args:
        path: (N + 1, n) configurations; the first is the starting point.
        t0: time of the first point [s].
        v0: velocity at the first point (n,).
        a0: acceleration at the first point (n,).
        max_velocity: per-joint speed limit (n,) [rad/s].
        max_acceleration: per-joint acceleration limit (n,) [rad/s^2].

    Returns:
        The trajectory, or None when the path is too short to stop on from
        ``v0`` within the acceleration limits (the caller keeps its previous
        trajectory, which does stop).
    """
    # Writeable contiguous copies, as the compiled passes are compiled for
    # (once, on import): a read-only array (a robot's limits) is another type
    # to numba, and compiled it for 1.7 s in the first brake of a fresh run.
    path = np.array(path, dtype=float, order="C")
    v0 = np.array(v0, dtype=float)
    path = _moved(path)  # without repeated points (steps that did not move)
    if len(path) < 2:
        if np.any(np.abs(v0) > 1e-9):
            return None
        return JointTrajectory.hold(t0, path[0])
    timed = _timing(
        path,
        float(t0),
        v0,
        np.array(a0, dtype=float),
        np.array(max_velocity, dtype=float),
        np.array(max_acceleration, dtype=float),
        _start_speed(v0, path[1] - path[0]),
    )
    if timed is None:
        return None
    times, velocities, accelerations = timed
    return JointTrajectory(times, path, velocities, accelerations)


#: A quintic from rest to rest over a unit distance in a unit time peaks at this
#: velocity (15/8, at mid-time) and this acceleration (10/sqrt(3)).
QUINTIC_PEAK_VELOCITY = 15.0 / 8.0
QUINTIC_PEAK_ACCELERATION = 10.0 / np.sqrt(3.0)

#: Directions within this cosine of the path's keep their full speed at a splice.
ALIGNED_COS = 0.7


def _start_speed(v0: FloatArray, d0: FloatArray) -> float:
    """Path speed (segments per second) that continues ``v0`` along segment ``d0``.

    The magnitude of ``v0`` is kept when it points within ~45 degrees of the path
    (a goal that moved a little turns the path a little; projecting would brake
    the robot at every splice), scaled down linearly to zero as it turns away
    beyond that. The first segment's blend from ``v0`` to the path direction
    deviates from the validated straight segment by about |dv| T / 8, a few
    millimetres at the joints' acceleration limits, which the links' padding
    covers.
    """
    speed = float(np.linalg.norm(v0))
    norm = float(np.linalg.norm(d0))
    if speed < 1e-12:
        return 0.0
    cos = float(v0.dot(d0)) / (speed * norm)
    return speed / norm * min(1.0, max(0.0, cos) / ALIGNED_COS)


@numba.njit(cache=True, nogil=True)
def _moved(path: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    """The path without the points that repeat the one before (within 1e-10)."""
    keep = np.ones(path.shape[0], dtype=np.bool_)
    for i in range(1, path.shape[0]):
        moved = False
        for j in range(path.shape[1]):
            if abs(path[i, j] - path[i - 1, j]) > 1e-10:
                moved = True
                break
        keep[i] = moved
    return path[keep]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _timing(
    path: FloatArray,
    t0: float,
    v0: FloatArray,
    a0: FloatArray,
    max_velocity: FloatArray,
    max_acceleration: FloatArray,
    start: float,
) -> tuple[FloatArray, FloatArray, FloatArray] | None:  # pragma: no cover - compiled
    """Times, velocities and accelerations of :func:`time_parameterize`'s path.

    ``start``: the path speed that continues ``v0`` (:func:`_start_speed`).
    None when the path is too short to stop on from there. The operations
    of the numpy version this replaced, in its order (the same numbers);
    division by zero gives inf as numpy's did (a joint that does not move).
    """
    n_points, n = path.shape
    segments = n_points - 1
    delta = np.empty((segments, n))
    seg_vel = np.empty(segments)  # path-speed limit per segment
    seg_acc = np.empty(segments)
    for i in range(segments):
        for j in range(n):
            delta[i, j] = path[i + 1, j] - path[i, j]
        fastest = max_velocity[0] / abs(delta[i, 0])
        hardest = max_acceleration[0] / abs(delta[i, 0])
        for j in range(1, n):
            fastest = min(fastest, max_velocity[j] / abs(delta[i, j]))
            hardest = min(hardest, max_acceleration[j] / abs(delta[i, j]))
        seg_vel[i], seg_acc[i] = fastest, hardest
    limit = np.empty(n_points)
    limit[0] = seg_vel[0]
    limit[n_points - 1] = seg_vel[segments - 1]
    for i in range(1, n_points - 1):
        limit[i] = min(seg_vel[i - 1], seg_vel[i])
        # Corners: turning from one segment's direction to the next within
        # about one segment's time needs |d_i - d_(i-1)| s'^2 <= a_max.
        corner = max_acceleration[0] / abs(delta[i, 0] - delta[i - 1, 0])
        for j in range(1, n):
            turn = abs(delta[i, j] - delta[i - 1, j])
            corner = min(corner, max_acceleration[j] / turn)
        limit[i] = min(limit[i], math.sqrt(corner))
    # Backward: able to stop at the end.
    speed2 = np.empty(n_points)
    for i in range(n_points):
        capped = min(limit[i], 1e12)
        speed2[i] = capped * capped
    speed2[n_points - 1] = 0.0
    for i in range(n_points - 2, -1, -1):
        speed2[i] = min(speed2[i], speed2[i + 1] + 2.0 * seg_acc[i])
    if start * start > speed2[0] * (1.0 + 1e-9) + 1e-12:
        return None
    # Forward: from the starting speed, within the acceleration limits.
    speed2[0] = start * start
    for i in range(n_points - 1):
        speed2[i + 1] = min(speed2[i + 1], speed2[i] + 2.0 * seg_acc[i])
    speed = np.sqrt(speed2)
    # Segment durations: unit path length at the mean of the end speeds, but
    # never longer than a quintic from rest to rest within the limits takes.
    # Slow ends (a start velocity nearly across the path, both ends near rest)
    # made the mean speed tiny and the segment seconds long, and the quintic
    # kept the starting velocity over all of it: off the path by radians.
    durations = np.empty(segments)
    for i in range(segments):
        at_mean = 1.0 / (0.5 * (speed[i] + speed[i + 1]))
        rest_to_rest = max(
            math.sqrt(QUINTIC_PEAK_ACCELERATION / seg_acc[i]),
            QUINTIC_PEAK_VELOCITY / seg_vel[i],
        )
        durations[i] = min(at_mean, rest_to_rest)
    velocities = np.empty((n_points, n))
    velocities[0] = v0
    velocities[n_points - 1] = 0.0
    for i in range(1, n_points - 1):
        for j in range(n):
            velocities[i, j] = 0.5 * (delta[i - 1, j] + delta[i, j]) * speed[i]
    change = abs(velocities[1, 0] - v0[0]) / max_acceleration[0]
    for j in range(1, n):
        change = max(change, abs(velocities[1, j] - v0[j]) / max_acceleration[j])
    durations[0] = max(durations[0], change)
    times = np.empty(n_points)
    times[0] = t0 + 0.0
    elapsed = 0.0
    for i in range(segments):
        elapsed += durations[i]
        times[i + 1] = t0 + elapsed
    accelerations = np.zeros((n_points, n))
    accelerations[0] = a0
    for i in range(1, n_points - 1):
        span = times[i + 1] - times[i - 1]
        for j in range(n):
            a = (velocities[i + 1, j] - velocities[i - 1, j]) / span
            bound = max_acceleration[j]
            accelerations[i, j] = -bound if a < -bound else (bound if a > bound else a)
    return times, velocities, accelerations


@numba.njit(cache=True, nogil=True)
def _sample(
    times: FloatArray,
    positions: FloatArray,
    velocities: FloatArray,
    accelerations: FloatArray,
    t: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover - compiled
    """:meth:`JointTrajectory.sample` in one call: find the segment, evaluate it."""
    n = times.size
    if t < times[0]:
        return positions[0], np.zeros(positions.shape[1]), np.zeros(positions.shape[1])
    if t >= times[n - 1]:
        last = positions[n - 1]
        return last, np.zeros(last.size), np.zeros(last.size)
    # The last point at or before t (numpy's searchsorted, side right, less one).
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if t < times[mid]:
            hi = mid
        else:
            lo = mid + 1
    i = lo - 1
    return _quintic(
        positions, velocities, accelerations, i, times[i + 1] - times[i], t - times[i]
    )


@numba.njit(cache=True, nogil=True)
def _quintic(
    positions: FloatArray,
    velocities: FloatArray,
    accelerations: FloatArray,
    i: int,
    T: float,
    dt: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover - compiled
    """Position, velocity, acceleration ``dt`` into segment ``i`` of duration T.

    The quintic matching both ends' position, velocity and acceleration, in
    the normalised time s = dt / T, joint by joint (the operations in the order
    numpy took them before this was compiled: the same numbers).
    """
    s = dt / T
    s2, s3 = s * s, s * s * s
    s4 = s3 * s
    s5 = s4 * s
    n = positions.shape[1]
    q = np.empty(n)
    dq = np.empty(n)
    ddq = np.empty(n)
    for j in range(n):
        p0, p1 = positions[i, j], positions[i + 1, j]
        v0, v1 = velocities[i, j] * T, velocities[i + 1, j] * T
        a0 = accelerations[i, j] * T * T
        a1 = accelerations[i + 1, j] * T * T
        dp = p1 - p0
        c2 = 0.5 * a0
        c3 = 10.0 * dp - 6.0 * v0 - 4.0 * v1 - 1.5 * a0 + 0.5 * a1
        c4 = -15.0 * dp + 8.0 * v0 + 7.0 * v1 + 1.5 * a0 - a1
        c5 = 6.0 * dp - 3.0 * v0 - 3.0 * v1 - 0.5 * a0 + 0.5 * a1
        q[j] = p0 + s * v0 + s2 * c2 + s3 * c3 + s4 * c4 + s5 * c5
        dq[j] = (v0 + 2.0 * s * c2 + 3.0 * s2 * c3 + 4.0 * s3 * c4 + 5.0 * s4 * c5) / T
        ddq[j] = (2.0 * c2 + 6.0 * s * c3 + 12.0 * s2 * c4 + 20.0 * s3 * c5) / (T * T)
    return q, dq, ddq


# Compiled (or loaded from numba's cache) on import, not in a run's first period.
_sample(np.array([0.0, 1.0]), np.zeros((2, 1)), np.zeros((2, 1)), np.zeros((2, 1)), 0.5)
_ONE = np.ones(1)
_timing(_moved(np.array([[0.0], [1.0], [2.0]])), 0.0, _ONE, _ONE, _ONE, _ONE, 0.0)


def stopping_trajectory(
    current: JointTrajectory, i: int, vmax: FloatArray, amax: FloatArray
) -> JointTrajectory | None:
    """Brake along ``current`` from its point ``i``, as soon as the limits allow.

    The path ahead was validated when it was planned; the shortest part of it
    from point ``i`` on which the robot can stop, timed by
    :func:`time_parameterize`, replaces the rest. None when the trajectory
    already stops no later than that (nothing to change).
    """
    t_s, _, v_s, a_s = current.point(i)
    ahead = current.positions[i:]
    # Binary search for the shortest prefix that can be stopped on (stoppable
    # prefixes are upward closed: a longer path leaves more room to brake). The
    # whole rest is not tried: when only it is stoppable, nothing changes.
    found: JointTrajectory | None = None
    lo, hi = 2, len(ahead)
    while lo < hi:
        mid = (lo + hi) // 2
        timed = time_parameterize(ahead[:mid], t_s, v_s, a_s, vmax, amax)
        if timed is None:
            lo = mid + 1
        else:
            hi, found = mid, timed
    return found


#: A trajectory braked on from the middle of a segment is resampled this
#: finely ahead [s]: its points are where the brake may end.
BRAKE_SAMPLE = 0.005


def braking_now(
    current: JointTrajectory, t: float, vmax: FloatArray, amax: FloatArray
) -> JointTrajectory | None:
    """Brake along ``current`` from time ``t``, as soon as the limits allow.

    As :func:`stopping_trajectory`, from the commanded state at ``t`` rather
    than from a point of ``current``: the rest of the motion is resampled
    every :data:`BRAKE_SAMPLE` so the brake can end between its points. None
    when the motion already stops by its next sample.
    """
    if t >= current.end_time:
        return None
    times = np.append(np.arange(t, current.end_time, BRAKE_SAMPLE), current.end_time)
    samples = [current.sample(float(u)) for u in times]
    dense = JointTrajectory(
        times,
        np.array([p for p, _, _ in samples]),
        np.array([v for _, v, _ in samples]),
        np.array([a for _, _, a in samples]),
    )
    return stopping_trajectory(dense, 0, vmax, amax)
