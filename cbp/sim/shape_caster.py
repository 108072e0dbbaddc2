# SPDX-License-Identifier: Apache-2.0
"""Depth images by a compiled ray cast of placed shapes, whatever engine holds them.

:class:`ShapeCaster` draws the parts of a scene, each a set of triangles (a
mesh, a box) or an analytic shape (a sphere, a cylinder, a capsule) at a
placement in the world, with the compiled pass of
:mod:`cbp.sim.ray_kernels`: for every pixel's ray, the nearest surface, in
PyBullet's depth buffer (:mod:`cbp.perception.frame`). An engine's caster says
which parts its scene has and where they are now: PyBullet's visual shapes
(:class:`cbp.sim.raycast.RayCaster`) or MuJoCo's geoms
(:class:`cbp.sim.mujoco.raycast.MujocoRayCaster`).

The parts that have never moved are drawn once per camera and kept; each
capture casts only the others over a copy (a fixed camera's shelf costs
nothing after its first frame, the arm as much as before). The images are
the same: each pixel keeps its nearest surface, in any order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cbp.robot import FloatArray
from cbp.sim.ray_kernels import cast, depth_buffer

__all__ = ["CastShape", "ShapeCaster", "box_triangles"]

#: A box's triangles, as corner indices (corners: bit 0 x, bit 1 y, bit 2 z).
_BOX_FACES = np.array(
    [
        [0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6],  # -z, +z
        [0, 1, 5], [0, 5, 4], [2, 6, 7], [2, 7, 3],  # -y, +y
        [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5],  # -x, +x
    ],
    dtype=np.intp,
)  # fmt: skip


@dataclass(frozen=True)
class CastShape:
    """One part's surface in its own frame: triangles, or an analytic shape."""

    triangles: FloatArray | None
    """(T, 3, 3) [m], or None for an analytic shape."""
    kind: int = -1
    """:data:`~cbp.sim.ray_kernels.SPHERE`, ``CYLINDER`` or ``CAPSULE``
    (analytic shapes, about the frame's z axis)."""
    radius: float = 0.0
    """[m]"""
    half_length: float = 0.0
    """Half the length of a cylinder or of a capsule's straight part [m]."""


def box_triangles(size: Sequence[float]) -> FloatArray:
    """The twelve triangles (12, 3, 3) of a box of ``size`` [m] about its centre."""
    half = 0.5 * np.asarray(size, dtype=float)
    corners = np.array(
        [[(-1) ** (1 - (i >> k & 1)) * half[k] for k in range(3)] for i in range(8)]
    )
    return np.asarray(corners[_BOX_FACES])


class ShapeCaster:
    """Depth images of placed parts by a compiled ray cast; a subclass places them.

    A subclass gives the parts (:meth:`_use`, when its scene's parts change,
    from :meth:`_sync`) and their placements now (:meth:`_placements`).
    """

    def __init__(self) -> None:
        """No parts until the subclass gives them."""
        self._triangles = np.zeros((0, 3, 3))
        self._tri_part = np.zeros(0, dtype=np.intp)
        self._shapes = np.zeros((0, 3))
        self._shape_part = np.zeros(0, dtype=np.intp)
        # Parts that never moved: their first placements; which moved since.
        self._first = np.zeros((0, 4, 4))
        self._moved = np.zeros(0, dtype=np.bool_)
        #: Per camera (its view, projection, size and planes): the depth of
        #: the parts that never moved, drawn once (the triangle and shape
        #: lists of the others are cast over a copy of it at each capture).
        self._still: dict[bytes, FloatArray] = {}

    def render(
        self,
        view: FloatArray,
        projection: FloatArray,
        width: int,
        height: int,
        near: float,
        far: float,
    ) -> FloatArray:
        """The depth buffer (height, width) seen through ``view`` and ``projection``.

        Args:
            view: world to camera (OpenGL convention: looking along -z), (4, 4).
            projection: a symmetric perspective projection (4, 4); only its
                focal terms are read.
            width: image width [px].
            height: image height [px].
            near: the clipping plane [m].
            far: the far plane [m].
        """
        self._sync()
        placements = self._placements()
        moved = self._moved
        now = np.any(placements != self._first, axis=(1, 2)) & ~moved
        if now.any():  # a part moves for the first time: drawn anew each time
            moved |= now
            self._still.clear()
        to_camera = np.einsum("ij,njk->nik", np.asarray(view, dtype=float), placements)
        fx, fy = float(projection[0, 0]), float(projection[1, 1])
        key = np.array([*np.ravel(view), fx, fy, width, height, near, far]).tobytes()
        still = self._still.get(key)
        if still is None:  # the parts that never moved, once per camera
            still = np.full((height, width), np.inf)
            cast(
                *self._lists(~moved),
                to_camera,
                fx,
                fy,
                float(near),
                float(far),
                still,
            )
            self._still[key] = still
        depth = still.copy()
        cast(*self._lists(moved), to_camera, fx, fy, float(near), float(far), depth)
        return depth_buffer(depth, float(near), float(far))

    def _sync(self) -> None:
        """Bring the parts up to the scene (:meth:`_use` if they changed)."""

    def _placements(self) -> FloatArray:
        """Each part's frame in the world now (P, 4, 4)."""
        raise NotImplementedError(f"{type(self).__name__} places no parts")

    def _use(self, shapes: Sequence[CastShape]) -> None:
        """Draw these parts from now on, one per placement, in order.

        Every part counts as still until it moves (:meth:`_placements` is read
        now, so the subclass knows the parts' placements before it calls).
        """
        triangles: list[FloatArray] = []
        tri_part: list[FloatArray] = []
        analytic: list[list[float]] = []
        shape_part: list[int] = []
        for k, shape in enumerate(shapes):
            if shape.triangles is not None:
                triangles.append(shape.triangles)
                tri_part.append(np.full(len(shape.triangles), k, dtype=np.intp))
            else:
                analytic.append([shape.kind, shape.radius, shape.half_length])
                shape_part.append(k)
        self._triangles = (
            np.concatenate(triangles) if triangles else np.zeros((0, 3, 3))
        )
        self._tri_part = (
            np.concatenate(tri_part) if tri_part else np.zeros(0, dtype=np.intp)
        )
        self._shapes = np.array(analytic, dtype=float).reshape(-1, 3)
        self._shape_part = np.array(shape_part, dtype=np.intp)
        self._first = self._placements()
        self._moved = np.zeros(len(self._first), dtype=np.bool_)
        self._still.clear()

    def _lists(
        self, parts: np.ndarray
    ) -> tuple[FloatArray, np.ndarray, FloatArray, np.ndarray]:
        """The flagged ``parts`` triangles and shapes, as :func:`cast` takes them."""
        tri = parts[self._tri_part]
        shape = parts[self._shape_part]
        return (
            self._triangles[tri],
            self._tri_part[tri],
            self._shapes[shape],
            self._shape_part[shape],
        )
