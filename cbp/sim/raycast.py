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
from cbp.sim.ray_kernels import CAPSULE, CYLINDER, SPHERE
from cbp.sim.shape_caster import CastShape, ShapeCaster, box_triangles

__all__ = ["RayCaster"]


@dataclass(frozen=True)
class _Part:
    """One visual shape of one body link."""

    body: int
    link: int
    local: FloatArray
    """The shape's frame in the link's frame (4, 4)."""
    shape: CastShape


def _pose(position: Sequence[float], quaternion: Sequence[float]) -> FloatArray:
    """A 4x4 transform from PyBullet's position and (x, y, z, w) quaternion."""
    M = np.eye(4)
    M[:3, :3] = np.array(pb.getMatrixFromQuaternion(quaternion)).reshape(3, 3)
    M[:3, 3] = position
    return M


class RayCaster(ShapeCaster):
    """Depth images of a PyBullet client's bodies, by a compiled ray cast.

    Bodies added to the client later (objects that appear) are found at the
    next capture; removed ones are dropped. Mesh files are read once each.
    What never moved is drawn once per camera (:class:`ShapeCaster`).

    Args:
        client: the PyBullet client id.
    """

    def __init__(self, client: int) -> None:
        """Nothing is read until the first capture."""
        super().__init__()
        self.client = client
        self._parts: dict[int, list[_Part]] = {}
        self._meshes: dict[tuple[str, tuple[float, ...]], FloatArray] = {}
        self._layout: tuple[tuple[int, tuple[object, ...]], ...] | None = None
        self._inertia: dict[int, FloatArray] = {}
        self._links: list[tuple[int, int]] = []
        self._part_link = np.zeros(0, dtype=np.intp)
        self._part_local = np.zeros((0, 4, 4))

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
        links: list[tuple[int, int]] = []
        part_link: list[int] = []
        parts = [part for b, _ in layout for part in self._parts[b]]
        for part in parts:
            key = (part.body, part.link)
            if key not in links:
                links.append(key)
            part_link.append(links.index(key))
        self._links = links
        self._part_link = np.array(part_link, dtype=np.intp)
        self._part_local = np.array([part.local for part in parts]).reshape(-1, 4, 4)
        self._use([part.shape for part in parts])

    def _read(self, shapes: tuple[Any, ...]) -> list[_Part]:
        """A body's visual shapes (``getVisualShapeData``), each in its link's frame."""
        parts = []
        for data in shapes:
            body, link, kind, dims, filename = data[:5]
            local = _pose(data[5], data[6])
            if kind == pb.GEOM_MESH:
                triangles = self._mesh(filename.decode(), tuple(dims))
                parts.append(_Part(body, link, local, CastShape(triangles)))
            elif kind == pb.GEOM_BOX:
                parts.append(_Part(body, link, local, CastShape(box_triangles(dims))))
            elif kind == pb.GEOM_SPHERE:
                parts.append(_Part(body, link, local, CastShape(None, SPHERE, dims[0])))
            elif kind in (pb.GEOM_CYLINDER, pb.GEOM_CAPSULE):
                code = CYLINDER if kind == pb.GEOM_CYLINDER else CAPSULE
                shape = CastShape(None, code, dims[1], dims[0] / 2)
                parts.append(_Part(body, link, local, shape))
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
