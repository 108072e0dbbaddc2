# SPDX-License-Identifier: Apache-2.0
"""One declared obstacle: a coal shape at a world placement, with its box.

A scenario's objects (boxes, spheres, cylinders, meshes) become
:class:`EnvironmentObject` records; a
:class:`~cbp.collision.objects.PrimitiveEnvironment` measures the robot
against them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.files import load_mesh
from cbp.robot import FloatArray

__all__ = ["EnvironmentObject"]


@dataclass(frozen=True)
class EnvironmentObject:
    """One declared obstacle: a coal shape at a world placement.

    Attributes:
        name: object name (from the scenario).
        shape: the coal shape (Box, Sphere, Cylinder, Convex or BVH mesh).
        placement: world placement of the shape's frame.
        lower: world AABB lower corner, (3,).
        upper: world AABB upper corner, (3,).
        allow_contact: robot links that may touch it (left out of its checks).
        velocity: its world-frame linear velocity [m/s] (a declared motion), for
            queries that look ahead (:class:`PrimitiveEnvironment`).
    """

    name: str
    shape: coal.CollisionGeometry
    placement: pin.SE3
    lower: FloatArray
    upper: FloatArray
    allow_contact: frozenset[str] = frozenset()
    velocity: FloatArray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def make(
        cls, name: str, shape: coal.CollisionGeometry, placement: pin.SE3
    ) -> EnvironmentObject:
        """Wrap a shape, computing its world bounding box."""
        shape.computeLocalAABB()
        lo = np.asarray(shape.aabb_local.min_, dtype=float)
        hi = np.asarray(shape.aabb_local.max_, dtype=float)
        corners = np.array(
            [
                [x, y, z]
                for x in (lo[0], hi[0])
                for y in (lo[1], hi[1])
                for z in (lo[2], hi[2])
            ]
        )
        world = corners.dot(placement.rotation.T) + placement.translation
        return cls(name, shape, placement, world.min(axis=0), world.max(axis=0))

    @classmethod
    def primitive(
        cls, name: str, kind: str, size: tuple[float, ...], placement: pin.SE3
    ) -> EnvironmentObject:
        """A box (edges x, y, z), sphere (radius) or cylinder (radius, length)."""
        if kind == "box":
            shape = coal.Box(*size)
        elif kind == "sphere":
            shape = coal.Sphere(size[0])
        elif kind == "cylinder":
            shape = coal.Cylinder(size[0], size[1])
        else:
            raise ConfigError(
                f"unknown primitive '{kind}'; expected box, sphere or cylinder"
            )
        return cls.make(name, shape, placement)

    @classmethod
    def mesh(
        cls, name: str, path: Path, scale: FloatArray, placement: pin.SE3
    ) -> EnvironmentObject:
        """A triangle mesh file (any format trimesh reads), kept non-convex."""
        mesh = load_mesh(path)
        mesh.apply_scale(scale)
        # coal 3's addSubModel takes its own vector types, not arrays.
        points = coal.StdVec_Vec3s()
        for v in np.asarray(mesh.vertices, dtype=float):
            points.append(v)
        triangles = coal.StdVec_Triangle()
        for a, b, c in np.asarray(mesh.faces).tolist():
            triangles.append(coal.Triangle(a, b, c))
        model = coal.BVHModelOBBRSS()
        model.beginModel(len(mesh.faces), len(mesh.vertices))
        model.addSubModel(points, triangles)
        model.endModel()
        return cls.make(name, model, placement)
