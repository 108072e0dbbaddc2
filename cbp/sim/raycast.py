# SPDX-License-Identifier: Apache-2.0
"""Depth images of a PyBullet scene by a compiled ray cast: no OpenGL, few ms.

:class:`RayCaster` reads the visual shapes of every body in a PyBullet client
(the robot's links and the scene's objects: the same shapes PyBullet's tiny
renderer draws) and, at each capture, their current placements. One compiled
pass then finds, for every pixel's ray, the nearest surface:

- triangles (meshes, and boxes as their twelve triangles) are visited one by
  one: each covers the pixels whose rays cross it, and a pixel keeps the
  nearest crossing (the exact ray-plane depth, so a triangle-major cast);
- spheres, cylinders and capsules are intersected analytically, ray by ray,
  over the pixels their bounding box covers: the true surface, where the tiny
  renderer draws a coarse polyhedron (measured: a sphere of 8 cm radius up to
  5 mm inside its surface, a cylinder of 5 cm up to 1.3 mm).

Pixels sample rays at PyBullet's convention (:mod:`cbp.perception.frame`);
surfaces nearer than the clipping plane are cut away (what lies behind shows)
and those at or beyond the far plane are not seen. The image is a depth buffer
in [0, 1] like the tiny renderer's (1 where nothing is seen).

Measured against the tiny renderer (``tests/sim/test_raycast.py``: the
boards and the shelf, three arm configurations, five fixed cameras and one on
the hand, 128 x 96): 99.9 % of all pixels agree within 1 mm of depth (both
see nothing, or both a surface that near), every image at least 98.9 %. The
rest lie on silhouette edges, or on triangles that cross the clipping plane,
whose depth the tiny renderer gets about 1 mm wrong (a camera under a shelf
board); there the cast depth is the plane's. A 320 x 240 frame of the shelf
takes about 1 ms here against 10-35 ms with the tiny renderer, and 600 ms
with PyBullet's ``rayTestBatch`` (one thread).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cbp.files import load_mesh
from cbp.robot import FloatArray
from cbp.sim.bullet import pb
from cbp.sim.ray_kernels import CAPSULE, CYLINDER, SPHERE, cast, depth_buffer

__all__ = ["RayCaster"]

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
class _Part:
    """One visual shape of one body link: triangles or an analytic shape."""

    body: int
    link: int
    local: FloatArray
    """The shape's frame in the link's frame (4, 4)."""
    triangles: FloatArray | None
    """(T, 3, 3) in the shape's frame, or None for an analytic shape."""
    kind: int = -1
    radius: float = 0.0
    half_length: float = 0.0


def _pose(position: Sequence[float], quaternion: Sequence[float]) -> FloatArray:
    """A 4x4 transform from PyBullet's position and (x, y, z, w) quaternion."""
    M = np.eye(4)
    M[:3, :3] = np.array(pb.getMatrixFromQuaternion(quaternion)).reshape(3, 3)
    M[:3, 3] = position
    return M


def _box_triangles(size: FloatArray) -> FloatArray:
    half = 0.5 * np.asarray(size, dtype=float)
    corners = np.array(
        [[(-1) ** (1 - (i >> k & 1)) * half[k] for k in range(3)] for i in range(8)]
    )
    return np.asarray(corners[_BOX_FACES])


class RayCaster:
    """Depth images of a PyBullet client's bodies, by a compiled ray cast.

    Bodies added to the client later (objects that appear) are found at the
    next capture; removed ones are dropped. Mesh files are read once each.
    The parts that have never moved are drawn once per camera and kept; each
    capture casts only the others over a copy (a fixed camera's shelf costs
    nothing after its first frame, the arm as much as before). The images
    are the same: each pixel keeps its nearest surface, in any order.

    Args:
        client: the PyBullet client id.
    """

    def __init__(self, client: int) -> None:
        """Nothing is read until the first capture."""
        self.client = client
        self._parts: dict[int, list[_Part]] = {}
        self._meshes: dict[tuple[str, tuple[float, ...]], FloatArray] = {}
        self._layout: tuple[tuple[int, tuple[object, ...]], ...] | None = None
        self._inertia: dict[int, FloatArray] = {}
        self._triangles = np.zeros((0, 3, 3))
        self._tri_part = np.zeros(0, dtype=np.intp)
        self._shapes = np.zeros((0, 3))
        self._shape_part = np.zeros(0, dtype=np.intp)
        self._links: list[tuple[int, int]] = []
        self._part_link = np.zeros(0, dtype=np.intp)
        self._part_local = np.zeros((0, 4, 4))
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

    def _sync(self) -> None:
        """Read the visual shapes of bodies new since the last capture.

        A body is known by its id and its visual shapes' description (PyBullet
        may give a removed body's id to a new one).
        """
        c = self.client
        layout = tuple(
            (b, tuple(pb.getVisualShapeData(b, physicsClientId=c)))
            for b in (
                pb.getBodyUniqueId(i, physicsClientId=c)
                for i in range(pb.getNumBodies(physicsClientId=c))
            )
        )
        if layout == self._layout:
            return
        known = dict(self._layout or ())
        self._parts = {
            b: self._parts[b] if known.get(b) == data else self._read(data)
            for b, data in layout
        }
        self._layout = layout
        ids = [b for b, _ in layout]
        links: list[tuple[int, int]] = []
        part_link: list[int] = []
        local: list[FloatArray] = []
        triangles: list[FloatArray] = []
        tri_part: list[FloatArray] = []
        shapes: list[list[float]] = []
        shape_part: list[int] = []
        for b in ids:
            for part in self._parts[b]:
                key = (part.body, part.link)
                if key not in links:
                    links.append(key)
                k = len(part_link)
                part_link.append(links.index(key))
                local.append(part.local)
                if part.triangles is not None:
                    triangles.append(part.triangles)
                    tri_part.append(np.full(len(part.triangles), k, dtype=np.intp))
                else:
                    shapes.append([part.kind, part.radius, part.half_length])
                    shape_part.append(k)
        self._links = links
        self._part_link = np.array(part_link, dtype=np.intp)
        self._part_local = np.array(local).reshape(-1, 4, 4)
        self._triangles = (
            np.concatenate(triangles) if triangles else np.zeros((0, 3, 3))
        )
        self._tri_part = (
            np.concatenate(tri_part) if tri_part else np.zeros(0, dtype=np.intp)
        )
        self._shapes = np.array(shapes, dtype=float).reshape(-1, 3)
        self._shape_part = np.array(shape_part, dtype=np.intp)
        self._first = self._placements()
        self._moved = np.zeros(len(self._first), dtype=np.bool_)
        self._still.clear()

    def _read(self, shapes: tuple[Any, ...]) -> list[_Part]:
        """A body's visual shapes (``getVisualShapeData``), each in its link's frame."""
        parts = []
        for data in shapes:
            body, link, kind, dims, filename = data[:5]
            local = _pose(data[5], data[6])
            if kind == pb.GEOM_MESH:
                triangles = self._mesh(filename.decode(), tuple(dims))
                parts.append(_Part(body, link, local, triangles))
            elif kind == pb.GEOM_BOX:
                parts.append(_Part(body, link, local, _box_triangles(dims)))
            elif kind == pb.GEOM_SPHERE:
                parts.append(_Part(body, link, local, None, SPHERE, dims[0]))
            elif kind in (pb.GEOM_CYLINDER, pb.GEOM_CAPSULE):
                code = CYLINDER if kind == pb.GEOM_CYLINDER else CAPSULE
                parts.append(_Part(body, link, local, None, code, dims[1], dims[0] / 2))
            else:
                raise ValueError(
                    f"body {body} link {link}: visual shape type {kind} cannot be "
                    "ray cast (boxes, spheres, cylinders, capsules and meshes can)"
                )
        return parts

    def _mesh(self, filename: str, scale: tuple[float, ...]) -> FloatArray:
        """A mesh file's triangles (T, 3, 3), scaled; read once per file and scale."""
        key = (filename, scale)
        if key not in self._meshes:
            mesh = load_mesh(Path(filename))
            vertices = np.asarray(mesh.vertices, dtype=float) * np.asarray(scale)
            self._meshes[key] = np.ascontiguousarray(vertices[np.asarray(mesh.faces)])
        return self._meshes[key]

    def _base_inertia(self, body: int) -> FloatArray:
        """The base's frame in its inertial frame (4, 4), read once per body."""
        if body not in self._inertia:
            info = pb.getDynamicsInfo(body, -1, physicsClientId=self.client)
            self._inertia[body] = np.asarray(np.linalg.inv(_pose(info[3], info[4])))
        return self._inertia[body]

    def _placements(self) -> FloatArray:
        """Each part's frame in the world now (P, 4, 4)."""
        c = self.client
        link_pose = np.empty((len(self._links), 4, 4))
        by_body: dict[int, list[int]] = {}
        for i, (body, _) in enumerate(self._links):
            by_body.setdefault(body, []).append(i)
        for body, rows in by_body.items():
            moving = [self._links[i][1] for i in rows if self._links[i][1] >= 0]
            states = (
                pb.getLinkStates(
                    body, moving, computeForwardKinematics=True, physicsClientId=c
                )
                if moving
                else []
            )
            k = 0
            for i in rows:
                if self._links[i][1] < 0:  # the base: its inertial frame
                    pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=c)
                    link_pose[i] = _pose(pos, orn).dot(self._base_inertia(body))
                else:  # the link's URDF frame
                    link_pose[i] = _pose(states[k][4], states[k][5])
                    k += 1
        return np.asarray(
            np.einsum("nij,njk->nik", link_pose[self._part_link], self._part_local)
        )
