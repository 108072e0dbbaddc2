# SPDX-License-Identifier: Apache-2.0
"""Convex hulls and their face planes: meshes and primitives into coal shapes.

A mesh becomes its convex hull (built with trimesh: the coal wheel has no
qhull); a URDF primitive keeps its coal shape, with a triangle mesh of it for
its planes and bounds. A hull's half-spaces ``n . x <= d`` are stacked as rows
(n, d), ordered so that point-inside tests reject early.
"""

from __future__ import annotations

from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import trimesh
from scipy.optimize import minimize

from cbp.errors import ConfigError
from cbp.files import load_mesh
from cbp.robot import FloatArray, IntArray

__all__ = [
    "beyond_planes",
    "face_planes",
    "fit_capsule",
    "hull_shape",
    "primitive_mesh",
    "transform_planes",
]


def hull_shape(path: Path, scale: FloatArray) -> tuple[coal.Convex, trimesh.Trimesh]:
    """A mesh file's convex hull, scaled: as a coal shape and as a trimesh."""
    mesh = load_mesh(path, "collision mesh")
    mesh.apply_scale(scale)
    hull = mesh.convex_hull
    points = coal.StdVec_Vec3s()
    for v in np.asarray(hull.vertices, dtype=float):
        points.append(v)
    triangles = coal.StdVec_Triangle()
    for a, b, c in np.asarray(hull.faces):
        triangles.append(coal.Triangle(int(a), int(b), int(c)))
    return coal.Convex(points, triangles), hull


def beyond_planes(points: FloatArray, planes: list[FloatArray]) -> float:
    """How far the farthest of ``points`` lies outside the nearest of some hulls.

    Per point, the distance beyond a hull's faces is its largest plane excess
    (n . x - d); the point is counted against the hull it is least beyond. 0
    when every point is inside a hull.
    """
    worst = 0.0
    for start in range(0, len(points), 4096):
        chunk = points[start : start + 4096]
        least = np.full(len(chunk), np.inf)
        for p in planes:
            least = np.minimum(least, (chunk.dot(p[:, :3].T) - p[:, 3]).max(axis=1))
        worst = max(worst, float(least.max()))
    return worst


def _segment_distances(points: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    ab = b - a
    t = np.clip((points - a).dot(ab) / max(float(ab.dot(ab)), 1e-12), 0.0, 1.0)
    return np.asarray(np.linalg.norm(points - (a + t[:, None] * ab), axis=1))


def fit_capsule(points: FloatArray) -> tuple[pin.SE3, float, float]:
    """The capsule of least volume (found locally) that contains ``points`` (n, 3).

    The axis starts on the points' principal axis; its ends and an offset of the
    axis are optimised (Nelder-Mead), with the radius set to the farthest point.

    Returns:
        (placement of the capsule's centre with its axis along local z, radius,
        full length of the axis segment).
    """
    centre = points.mean(axis=0)
    axis = np.linalg.svd(points - centre)[2][0]
    along = (points - centre).dot(axis)

    def ends(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        return centre + x[2:] + axis * x[0], centre + x[2:] + axis * x[1]

    def volume(x: FloatArray) -> float:
        a, b = ends(x)
        r = float(_segment_distances(points, a, b).max())
        return float(np.pi * r * r * np.linalg.norm(b - a) + 4.0 / 3.0 * np.pi * r**3)

    x0 = np.array([0.7 * along.min(), 0.7 * along.max(), 0.0, 0.0, 0.0])
    x = minimize(volume, x0, method="Nelder-Mead", options={"maxiter": 3000}).x
    a, b = ends(x)
    radius = float(_segment_distances(points, a, b).max())
    length = float(np.linalg.norm(b - a))
    z = (b - a) / length if length > 1e-9 else np.array([0.0, 0.0, 1.0])
    rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), z).matrix()
    return pin.SE3(rotation, 0.5 * (a + b)), radius, length


def primitive_mesh(shape: coal.ShapeBase) -> trimesh.Trimesh:
    """A triangle mesh of a coal box, sphere, cylinder or capsule."""
    if isinstance(shape, coal.Box):
        return trimesh.creation.box(extents=2.0 * np.asarray(shape.halfSide))
    if isinstance(shape, coal.Sphere):
        return trimesh.creation.icosphere(subdivisions=2, radius=shape.radius)
    if isinstance(shape, coal.Cylinder):
        return trimesh.creation.cylinder(
            radius=shape.radius, height=2.0 * shape.halfLength
        )
    if isinstance(shape, coal.Capsule):
        return trimesh.creation.capsule(
            radius=shape.radius, height=2.0 * shape.halfLength
        )
    raise ConfigError(f"unsupported collision primitive {type(shape).__name__}")


def face_planes(hull: trimesh.Trimesh) -> FloatArray:
    """A hull's half-spaces (F, 4), one per plane, normals spread (rejects early)."""
    normals = np.asarray(hull.face_normals, dtype=float)
    offsets = np.einsum("ij,ij->i", normals, hull.triangles[:, 0, :])
    planes = np.hstack([normals, offsets[:, None]])
    # Coplanar triangles repeat a plane: keep one of each.
    planes = np.unique(np.round(planes, 9), axis=0)
    return planes[_spread_order(planes[:, :3])]


def _spread_order(normals: FloatArray) -> IntArray:
    """An order of the faces in which each next normal is the least like those before.

    Point-inside tests stop at the first plane a point lies beyond; with the
    normals spread this way, a point outside the hull is usually rejected within
    the first few planes (in sorted order, neighbouring planes face alike).
    """
    order = [0]
    likeness = normals.dot(normals[0])
    for _ in range(len(normals) - 1):
        likeness[order[-1]] = np.inf
        k = int(np.argmin(likeness))
        order.append(k)
        likeness = np.maximum(likeness, normals.dot(normals[k]))
    return np.asarray(order, dtype=np.int64)


def transform_planes(planes: FloatArray, placement: pin.SE3) -> FloatArray:
    """Half-spaces n.x <= d of a shape, moved from its own frame by ``placement``."""
    normals = planes[:, :3].dot(placement.rotation.T)
    offsets = planes[:, 3] + normals.dot(placement.translation)
    return np.hstack([normals, offsets[:, None]])
