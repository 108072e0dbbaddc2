# SPDX-License-Identifier: Apache-2.0
"""The robot shapes' world placements from the configuration, compiled.

A compiled contact query takes the shapes' placements as one (n, 4, 4) array.
Read from pinocchio's geometry data, one placement at a time, they cost about
a microsecond each (an SE3 object, then its matrix): more than the narrow
phase of a whole query. This module computes them from ``q`` in one compiled
call: each joint's placement from its parent's, its fixed placement and its
motion, then each shape's from its joint's and the shape's fixed placement on
it. The same numbers as pinocchio's forward kinematics, for the joints robots
here use (revolute, prismatic, about any axis; unbounded revolute; planar;
free flyer); a model with another joint falls back to pinocchio.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from cbp.robot import FloatArray, IntArray

__all__ = ["ShapeKinematics", "place_shapes"]

#: Joint motions :func:`place_shapes` knows.
REVOLUTE, PRISMATIC, UNBOUNDED, PLANAR, FREE = 0, 1, 2, 3, 4

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class ShapeKinematics:
    """A model's joints and the shapes on them, packed for :func:`place_shapes`.

    Attributes:
        parent: each joint's parent joint (joint 0 is the world), (J,).
        motion: each joint's kind (:data:`REVOLUTE`, ...), (J,).
        axis: its axis (revolute and prismatic kinds), (J, 3).
        q_index: its first entry in ``q``, (J,).
        placement: its placement in its parent's frame at q = 0, (J, 4, 4).
        shape_joint: the joint that carries each shape, (n,).
        shape_placement: each shape's placement in its joint's frame, (n, 4, 4).
    """

    parent: npt.NDArray[np.int64]
    motion: npt.NDArray[np.int64]
    axis: FloatArray
    q_index: npt.NDArray[np.int64]
    placement: FloatArray
    shape_joint: npt.NDArray[np.int64]
    shape_placement: FloatArray

    @classmethod
    def build(
        cls, model: pin.Model, joints: list[int], placements: list[pin.SE3]
    ) -> ShapeKinematics | None:
        """The packing for shapes on ``joints`` at ``placements`` on them.

        None if the model has a joint :func:`place_shapes` does not know.
        """
        count = model.njoints
        motion = np.zeros(count, dtype=np.int64)
        axis = np.zeros((count, 3))
        for j in range(1, count):
            joint = model.joints[j]
            name = joint.shortname().removeprefix("JointModel")
            if name in ("RX", "RY", "RZ"):
                motion[j], axis[j] = REVOLUTE, _AXES[name[1]]
            elif name in ("PX", "PY", "PZ"):
                motion[j], axis[j] = PRISMATIC, _AXES[name[1]]
            elif name in ("RUBX", "RUBY", "RUBZ"):
                motion[j], axis[j] = UNBOUNDED, _AXES[name[3]]
            elif name == "RevoluteUnaligned":
                motion[j], axis[j] = REVOLUTE, joint.extract().axis
            elif name == "PrismaticUnaligned":
                motion[j], axis[j] = PRISMATIC, joint.extract().axis
            elif name == "Planar":
                motion[j] = PLANAR
            elif name == "FreeFlyer":
                motion[j] = FREE
            else:
                return None
        return cls(
            parent=np.array(model.parents, dtype=np.int64),
            motion=motion,
            axis=axis,
            q_index=np.array([max(j.idx_q, 0) for j in model.joints], dtype=np.int64),
            placement=np.array(
                [M.homogeneous for M in model.jointPlacements], dtype=float
            ).reshape(-1, 4, 4),
            shape_joint=np.array(joints, dtype=np.int64),
            shape_placement=np.array(
                [M.homogeneous for M in placements], dtype=float
            ).reshape(-1, 4, 4),
        )

    def __call__(self, q: FloatArray) -> FloatArray:
        """The shapes' world placements at ``q``, (n, 4, 4)."""
        out = np.empty((len(self.shape_joint), 4, 4))
        place_shapes(
            np.asarray(q, dtype=float),
            self.parent,
            self.motion,
            self.axis,
            self.q_index,
            self.placement,
            self.shape_joint,
            self.shape_placement,
            out,
        )
        return out


@numba.njit(cache=True, nogil=True, inline="always")
def _times(A: FloatArray, B: FloatArray, out: FloatArray) -> None:
    """Out = A B for rigid transforms (4, 4) (the last row is kept as is)."""
    for r in range(3):
        a0, a1, a2 = A[r, 0], A[r, 1], A[r, 2]
        for c in range(4):
            out[r, c] = a0 * B[0, c] + a1 * B[1, c] + a2 * B[2, c]
        out[r, 3] += A[r, 3]
    out[3, 0] = out[3, 1] = out[3, 2] = 0.0
    out[3, 3] = 1.0


@numba.njit(cache=True, nogil=True)
def place_shapes(
    q: FloatArray,
    parent: IntArray,
    motion: IntArray,
    axis: FloatArray,
    q_index: IntArray,
    placement: FloatArray,
    shape_joint: IntArray,
    shape_placement: FloatArray,
    out: FloatArray,
) -> None:
    """Write the shapes' world placements at ``q`` to ``out`` (n, 4, 4).

    The arrays are :class:`ShapeKinematics`' fields.
    """
    count = len(parent)
    world = np.empty((count, 4, 4))
    local = np.eye(4)
    step = np.empty((4, 4))
    world[0] = np.eye(4)
    for j in range(1, count):
        k = q_index[j]
        local[:] = 0.0
        local[3, 3] = 1.0
        kind = motion[j]
        if kind == PRISMATIC:
            for a in range(3):
                local[a, a] = 1.0
                local[a, 3] = axis[j, a] * q[k]
        elif kind in (REVOLUTE, UNBOUNDED):
            if kind == REVOLUTE:
                c, s = math.cos(q[k]), math.sin(q[k])
            else:
                c, s = q[k], q[k + 1]
            x, y, z = axis[j, 0], axis[j, 1], axis[j, 2]
            t = 1.0 - c
            local[0, 0] = c + t * x * x
            local[0, 1] = t * x * y - s * z
            local[0, 2] = t * x * z + s * y
            local[1, 0] = t * x * y + s * z
            local[1, 1] = c + t * y * y
            local[1, 2] = t * y * z - s * x
            local[2, 0] = t * x * z - s * y
            local[2, 1] = t * y * z + s * x
            local[2, 2] = c + t * z * z
        elif kind == PLANAR:
            c, s = q[k + 2], q[k + 3]
            local[0, 0], local[0, 1], local[0, 3] = c, -s, q[k]
            local[1, 0], local[1, 1], local[1, 3] = s, c, q[k + 1]
            local[2, 2] = 1.0
        else:  # FREE: translation, then the unit quaternion (x, y, z, w)
            x, y, z, w = q[k + 3], q[k + 4], q[k + 5], q[k + 6]
            local[0, 0] = 1.0 - 2.0 * (y * y + z * z)
            local[0, 1] = 2.0 * (x * y - z * w)
            local[0, 2] = 2.0 * (x * z + y * w)
            local[1, 0] = 2.0 * (x * y + z * w)
            local[1, 1] = 1.0 - 2.0 * (x * x + z * z)
            local[1, 2] = 2.0 * (y * z - x * w)
            local[2, 0] = 2.0 * (x * z - y * w)
            local[2, 1] = 2.0 * (y * z + x * w)
            local[2, 2] = 1.0 - 2.0 * (x * x + y * y)
            local[0, 3], local[1, 3], local[2, 3] = q[k], q[k + 1], q[k + 2]
        _times(world[parent[j]], placement[j], step)
        _times(step, local, world[j])
    for s in range(len(shape_joint)):
        _times(world[shape_joint[s]], shape_placement[s], out[s])
