"""Quintic trajectories, splicing, and timing that stops at the path's end."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from cbp.sim.trajectory import JointTrajectory, SpliceError, time_parameterize

VMAX = np.array([1.0, 2.0])
AMAX = np.array([4.0, 8.0])


def _samples(traj: JointTrajectory, n: int = 2000) -> tuple[np.ndarray, ...]:
    ts = np.linspace(traj.start_time, traj.end_time, n)
    q, v, a = zip(*(traj.sample(t) for t in ts), strict=True)
    return ts, np.array(q), np.array(v), np.array(a)


def test_quintic_meets_every_point_and_is_smooth() -> None:
    """Positions, velocities and accelerations match at the points; no jumps."""
    rng = np.random.default_rng(1)
    times = np.array([0.0, 0.3, 0.5, 1.1])
    traj = JointTrajectory(
        times, rng.normal(size=(4, 2)), rng.normal(size=(4, 2)), rng.normal(size=(4, 2))
    )
    for i, t in enumerate(times[:-1]):
        q, v, a = traj.sample(float(t))
        np.testing.assert_allclose(q, traj.positions[i], atol=1e-12)
        np.testing.assert_allclose(v, traj.velocities[i], atol=1e-12)
        np.testing.assert_allclose(a, traj.accelerations[i], atol=1e-10)
    # Approaching each interior point from the left gives the same values.
    for i in (1, 2):
        q, v, a = traj.sample(float(times[i]) - 1e-9)
        np.testing.assert_allclose(q, traj.positions[i], atol=1e-6)
        np.testing.assert_allclose(v, traj.velocities[i], atol=1e-5)
        np.testing.assert_allclose(a, traj.accelerations[i], atol=1e-3)
    # After the end: at rest at the last point.
    q, v, a = traj.sample(5.0)
    np.testing.assert_array_equal(q, traj.positions[-1])
    assert not v.any()
    assert not a.any()


def test_splice_keeps_the_prefix_and_refuses_a_jump() -> None:
    """A new trajectory starting on the old one replaces it from there on."""
    old = time_parameterize(
        np.linspace([0.0, 0.0], [1.0, 0.5], 50),
        0.0,
        np.zeros(2),
        np.zeros(2),
        VMAX,
        AMAX,
    )
    assert old is not None
    i = old.first_point_after(0.3)
    assert i is not None
    t_s, q_s, v_s, a_s = old.point(i)
    path = np.linspace(q_s, [0.2, 0.9], 40)
    new = time_parameterize(path, t_s, v_s, a_s, VMAX, AMAX)
    assert new is not None
    spliced = old.splice(new)
    np.testing.assert_allclose(spliced.sample(0.2)[0], old.sample(0.2)[0])
    np.testing.assert_allclose(spliced.sample(t_s + 0.1)[0], new.sample(t_s + 0.1)[0])
    np.testing.assert_allclose(spliced.positions[-1], [0.2, 0.9])
    jump = JointTrajectory.hold(t_s, q_s + 0.01)
    with pytest.raises(SpliceError, match="does not start on the current one"):
        old.splice(jump)


def test_time_parameterization_respects_limits_and_stops() -> None:
    """From rest: within the velocity limits, at rest at the end, on the path."""
    path = np.stack([np.linspace(0, 1.5, 80), np.linspace(0, -2.0, 80) ** 2 / 4], 1)
    traj = time_parameterize(path, 1.0, np.zeros(2), np.zeros(2), VMAX, AMAX)
    assert traj is not None
    _, q, v, a = _samples(traj)
    assert np.all(np.abs(v) <= VMAX * 1.02)
    # Between points the quintic blends a bang-bang profile: allow its overshoot.
    assert np.all(np.abs(a) <= AMAX * 1.5)
    np.testing.assert_allclose(q[-1], path[-1])
    np.testing.assert_allclose(v[-1], 0.0, atol=1e-9)
    # Time-optimal within a few percent: rest-to-rest on joint 1 (the binding one).
    bang = 2 * np.sqrt(1.5 / AMAX[0])
    assert traj.end_time - 1.0 >= bang * 0.98


def test_a_path_too_short_to_stop_on_is_refused() -> None:
    """Moving at 1 rad/s, a 1 cm path cannot be stopped on at 4 rad/s^2."""
    path = np.linspace([0.0, 0.0], [0.01, 0.0], 5)
    assert (
        time_parameterize(path, 0.0, np.array([1.0, 0.0]), np.zeros(2), VMAX, AMAX)
        is None
    )
    # ... but 20 cm can: v^2 / (2 a) = 12.5 cm.
    path = np.linspace([0.0, 0.0], [0.2, 0.0], 40)
    traj = time_parameterize(path, 0.0, np.array([1.0, 0.0]), np.zeros(2), VMAX, AMAX)
    assert traj is not None
    np.testing.assert_allclose(traj.velocities[0], [1.0, 0.0])


def test_a_still_path_holds() -> None:
    """A path that does not move is a hold (at rest), refused if moving."""
    path = np.zeros((3, 2))
    traj = time_parameterize(path, 2.0, np.zeros(2), np.zeros(2), VMAX, AMAX)
    assert traj is not None
    assert len(traj) == 1
    assert time_parameterize(path, 2.0, np.ones(2), np.zeros(2), VMAX, AMAX) is None


def _numpy_sample(tr: JointTrajectory, t: float) -> tuple[np.ndarray, ...]:
    """The quintic between two points, written with numpy (the reference)."""
    i = int(np.searchsorted(tr.times, t, side="right")) - 1
    T = tr.times[i + 1] - tr.times[i]
    s = (t - tr.times[i]) / T
    p0, p1 = tr.positions[i], tr.positions[i + 1]
    v0, v1 = tr.velocities[i] * T, tr.velocities[i + 1] * T
    a0, a1 = tr.accelerations[i] * T * T, tr.accelerations[i + 1] * T * T
    dp = p1 - p0
    c = [
        p0,
        v0,
        0.5 * a0,
        10 * dp - 6 * v0 - 4 * v1 - 1.5 * a0 + 0.5 * a1,
        -15 * dp + 8 * v0 + 7 * v1 + 1.5 * a0 - a1,
        6 * dp - 3 * v0 - 3 * v1 - 0.5 * a0 + 0.5 * a1,
    ]
    s2, s3, s4 = s * s, s * s * s, s * s * s * s
    q = c[0] + s * c[1] + s2 * c[2] + s3 * c[3] + s4 * c[4] + s4 * s * c[5]
    dq = c[1] + 2 * s * c[2] + 3 * s2 * c[3] + 4 * s3 * c[4] + 5 * s4 * c[5]
    ddq = 2 * c[2] + 6 * s * c[3] + 12 * s2 * c[4] + 20 * s3 * c[5]
    return q, dq / T, ddq / (T * T)


def test_compiled_sampling_gives_the_numpy_formula_s_numbers() -> None:
    """Sampling between points is bit for bit the quintic written in numpy."""
    rng = np.random.default_rng(5)
    n = 30
    times = np.cumsum(rng.uniform(1e-4, 0.05, n))
    tr = JointTrajectory(
        times, rng.normal(size=(n, 7)), rng.normal(size=(n, 7)), rng.normal(size=(n, 7))
    )
    for t in rng.uniform(times[0], times[-1], 500):
        for got, expected in zip(tr.sample(t), _numpy_sample(tr, t), strict=True):
            np.testing.assert_array_equal(got, expected)


def _numpy_timing(
    path: np.ndarray,
    t0: float,
    v0: np.ndarray,
    a0: np.ndarray,
    vmax: np.ndarray,
    amax: np.ndarray,
) -> tuple[np.ndarray, ...] | None:
    """time_parameterize's times, path, velocities, accelerations, in numpy."""
    moved = np.concatenate([[True], np.any(np.abs(np.diff(path, axis=0)) > 1e-10, 1)])
    path = path[moved]
    if len(path) < 2:
        return None
    delta = np.diff(path, axis=0)
    with np.errstate(divide="ignore", over="ignore"):
        seg_vel = np.min(vmax / np.abs(delta), axis=1)
        seg_acc = np.min(amax / np.abs(delta), axis=1)
        corner = np.sqrt(np.min(amax / np.abs(np.diff(delta, axis=0)), axis=1))
    limit = np.concatenate(
        [seg_vel[:1], np.minimum(seg_vel[:-1], seg_vel[1:]), seg_vel[-1:]]
    )
    limit[1:-1] = np.minimum(limit[1:-1], corner)
    speed2 = np.minimum(limit, 1e12) ** 2
    speed2[-1] = 0.0
    for i in range(len(path) - 2, -1, -1):
        speed2[i] = min(speed2[i], speed2[i + 1] + 2.0 * seg_acc[i])
    speed, norm = float(np.linalg.norm(v0)), float(np.linalg.norm(delta[0]))
    start = 0.0
    if speed >= 1e-12:
        cos = float(v0.dot(delta[0])) / (speed * norm)
        start = speed / norm * min(1.0, max(0.0, cos) / 0.7)
    if start * start > speed2[0] * (1.0 + 1e-9) + 1e-12:
        return None
    speed2[0] = start * start
    for i in range(len(path) - 1):
        speed2[i + 1] = min(speed2[i + 1], speed2[i] + 2.0 * seg_acc[i])
    speed = np.sqrt(speed2)
    with np.errstate(divide="ignore"):
        durations = np.minimum(
            1.0 / (0.5 * (speed[:-1] + speed[1:])),
            np.maximum(np.sqrt(10.0 / np.sqrt(3.0) / seg_acc), 15.0 / 8.0 / seg_vel),
        )
    velocities = np.zeros_like(path)
    velocities[0] = v0
    velocities[1:-1] = 0.5 * (delta[:-1] + delta[1:]) * speed[1:-1, None]
    durations[0] = max(durations[0], float(np.max(np.abs(velocities[1] - v0) / amax)))
    times = t0 + np.concatenate([[0.0], np.cumsum(durations)])
    accelerations = np.zeros_like(path)
    accelerations[0] = a0
    accelerations[1:-1] = np.clip(
        (velocities[2:] - velocities[:-2]) / (times[2:] - times[:-2])[:, None],
        -amax,
        amax,
    )
    return times, path, velocities, accelerations


def test_compiled_timing_gives_the_numpy_version_s_numbers() -> None:
    """Timing a path is bit for bit the numpy version it replaced (kept above)."""
    rng = np.random.default_rng(1)
    timed = 0
    for _ in range(500):
        n, points = int(rng.integers(1, 8)), int(rng.integers(2, 60))
        scale = rng.choice([1e-3, 1e-2, 0.1])
        path = np.cumsum(rng.normal(scale=scale, size=(points, n)), axis=0)
        path[rng.integers(1, points)] = path[0]  # a repeated point, perhaps
        if rng.random() < 0.2:
            path[:, 0] = 0.3  # a joint that does not move
        v0 = rng.normal(scale=rng.choice([0.0, 0.1, 1.0]), size=n)
        a0 = rng.normal(size=n)
        vmax, amax = rng.uniform(0.5, 2.5, n), rng.uniform(1.0, 10.0, n)
        t0 = float(rng.uniform(0.0, 10.0))
        got = time_parameterize(path, t0, v0, a0, vmax, amax)
        expected = _numpy_timing(path, t0, v0, a0, vmax, amax)
        if got is None or len(got) == 1:
            assert expected is None
            continue
        assert expected is not None
        timed += 1
        for field, value in zip(
            ("times", "positions", "velocities", "accelerations"), expected, strict=True
        ):
            np.testing.assert_array_equal(getattr(got, field), value)
    assert timed > 300


@pytest.mark.parametrize("turn_deg", [60.0, 80.0, 89.0, 89.9])
def test_a_path_that_turns_from_the_starting_velocity_brakes_near_it(
    turn_deg: float,
) -> None:
    """A short path at an angle to the motion: stop on it, do not coast off it.

    The speed along the path starts at the velocity's small component along it;
    the first segment was timed at that speed (25 s for 2 cm in a CAT run),
    while the quintic kept the full starting velocity for all of it and carried
    a joint 2.5 rad past its limit.
    """
    v0 = 0.3 * np.array([np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))])
    path = np.array([[0.0, 0.0], [0.02, 0.0]])
    traj = time_parameterize(path, 0.0, v0, np.zeros(2), VMAX, AMAX)
    assert traj is not None
    _, q, v, _ = _samples(traj)
    # Off the path by at most twice what braking from v0 costs (v^2 / 2a per
    # joint): a quintic brakes less sharply than bang-bang.
    braking = 2 * v0**2 / (2 * AMAX)
    assert np.all(q.min(axis=0) >= path.min(axis=0) - braking - 1e-3)
    assert np.all(q.max(axis=0) <= path.max(axis=0) + braking + 1e-3)
    assert np.all(np.abs(v) <= VMAX * 1.02)
    assert traj.end_time < 1.0


@settings(max_examples=200, deadline=None)
@given(
    steps=hnp.arrays(np.float64, (6, 2), elements=st.floats(-0.005, 0.005)),
    v0=hnp.arrays(np.float64, 2, elements=st.floats(-0.5, 0.5)),
)
def test_a_timed_path_never_strays_further_than_braking_takes_it(steps, v0) -> None:
    """Any path of QP-sized steps, any starting velocity: the samples stay near it.

    Within the path's box widened by twice the braking distance from ``v0``
    (see above) and 5 mm for the quintic's blending where the first segment is
    lengthened for a change of direction (3.9 mm at most over 3000 random
    cases).
    """
    path = np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])
    traj = time_parameterize(path, 0.0, v0, np.zeros(2), VMAX, AMAX)
    if traj is None:  # too short to stop on: the caller keeps its trajectory
        return
    _, q, _, _ = _samples(traj, 400)
    margin = v0**2 / AMAX + 5e-3
    assert np.all(q.min(axis=0) >= path.min(axis=0) - margin)
    assert np.all(q.max(axis=0) <= path.max(axis=0) + margin)
