# SPDX-License-Identifier: Apache-2.0
"""What a pinocchio model's joints say: limits, units, the support, random positions.

Functions of a ``pinocchio.Model`` alone, computed once when a
:class:`~cbp.robot.RobotModel` wraps it.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import pinocchio as pin

from cbp.robot.arrays import FloatArray, IntArray

__all__ = [
    "UNBOUNDED",
    "bounded_coordinates",
    "coordinate_names",
    "coordinate_units",
    "position_limits",
    "sample_joints",
    "support_matrix",
    "velocity_limits",
]

#: Pinocchio marks an unbounded coordinate with the largest double; treat anything this
#: large as no bound at all.
UNBOUNDED = 1e300


def position_limits(model: pin.Model) -> tuple[FloatArray, FloatArray]:
    """(lower, upper) position limits (nq each); ±inf where unbounded."""
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    lower[lower <= -UNBOUNDED] = -np.inf
    upper[upper >= UNBOUNDED] = np.inf
    return lower, upper


def velocity_limits(model: pin.Model) -> FloatArray:
    """The URDF's velocity limits (nv) [rad/s or m/s]; +inf where none is given."""
    velocity = np.array(model.velocityLimit, dtype=float)
    velocity[(velocity <= 0) | (velocity >= UNBOUNDED)] = np.inf
    return velocity


def bounded_coordinates(
    model: pin.Model, lower: FloatArray, upper: FloatArray
) -> tuple[IntArray, IntArray]:
    """(q indices, v indices) of the scalar coordinates with a finite range.

    What a joint-limit constraint bounds: one-coordinate joints (revolute,
    prismatic) whose two limits are finite.
    """
    bounded_q: list[int] = []
    bounded_v: list[int] = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        if joint.nq == 1 and joint.nv == 1:
            iq, iv = joint.idx_q, joint.idx_v
            if np.isfinite(lower[iq]) and np.isfinite(upper[iq]):
                bounded_q.append(iq)
                bounded_v.append(iv)
    return np.array(bounded_q, dtype=np.intp), np.array(bounded_v, dtype=np.intp)


def support_matrix(model: pin.Model) -> FloatArray:
    """``support[j, v]``: 1 where velocity coordinate v moves joint j's body, else 0.

    v moves j's body when it belongs to a joint on the path from the root to
    j. Shape (njoints, nv), read-only.
    """
    support = np.zeros((model.njoints, model.nv))
    for j in range(model.njoints):
        for k in model.supports[j]:
            if k > 0:
                joint = model.joints[k]
                support[j, joint.idx_v : joint.idx_v + joint.nv] = 1.0
    support.flags.writeable = False
    return support


def coordinate_names(model: pin.Model, space: Literal["q", "v"]) -> list[str]:
    """One name per configuration (``q``) or velocity (``v``) coordinate.

    A joint with one coordinate lends it its name; a joint with several (a
    planar or floating base) numbers them: ``root_0``, ``root_1``, ...
    """
    names = []
    for i in range(1, model.njoints):
        joint, name = model.joints[i], model.names[i]
        n = int(joint.nq if space == "q" else joint.nv)
        names += [name] if n == 1 else [f"{name}_{k}" for k in range(n)]
    return names


def coordinate_units(model: pin.Model, space: Literal["q", "v"]) -> list[str]:
    """The unit of each coordinate of :func:`coordinate_names`: ``m`` or ``rad``.

    A prismatic joint's coordinate is in metres, a revolute or continuous
    joint's in radians (a continuous joint's cosine and sine count as
    radians); a planar base's are x, y [m] then its heading, a floating
    base's a position [m] then a rotation.
    """
    units: list[str] = []
    for i in range(1, model.njoints):
        joint = model.joints[i]
        n = int(joint.nq if space == "q" else joint.nv)
        kind = joint.shortname()  # JointModelPX/PY/PZ, JointModelPrismatic...
        if kind == "JointModelPlanar":
            units += ["m", "m"] + ["rad"] * (n - 2)
        elif kind == "JointModelFreeFlyer":
            units += ["m"] * 3 + ["rad"] * (n - 3)
        elif kind.startswith("JointModelPrismatic") or kind[-2:-1] == "P":
            units += ["m"] * n
        else:
            units += ["rad"] * n
    return units


def sample_joints(
    model: pin.Model,
    q: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    rng: np.random.Generator,
) -> None:
    """Write into ``q`` each joint's position drawn uniformly in [lower, upper].

    Rotations of planar, floating and continuous joints are uniform (a
    normalised Gaussian quaternion, an angle in [-pi, pi)); ``lower`` and
    ``upper`` must be finite.
    """
    for j in range(1, model.njoints):
        joint = model.joints[j]
        iq, nq = joint.idx_q, joint.nq
        kind = joint.shortname()
        if kind == "JointModelFreeFlyer":
            q[iq : iq + 3] = rng.uniform(lower[iq : iq + 3], upper[iq : iq + 3])
            quat = rng.normal(size=4)
            q[iq + 3 : iq + 7] = quat / np.linalg.norm(quat)
        elif kind == "JointModelPlanar":
            q[iq : iq + 2] = rng.uniform(lower[iq : iq + 2], upper[iq : iq + 2])
            angle = rng.uniform(-np.pi, np.pi)
            q[iq + 2 : iq + 4] = (np.cos(angle), np.sin(angle))
        elif nq == 2 and joint.nv == 1:  # continuous joint: (cos, sin)
            angle = rng.uniform(-np.pi, np.pi)
            q[iq : iq + 2] = (np.cos(angle), np.sin(angle))
        else:
            q[iq : iq + nq] = rng.uniform(lower[iq : iq + nq], upper[iq : iq + nq])
