# SPDX-License-Identifier: Apache-2.0
"""Accuracy of contact normals against voxelised surfaces: raw, metaball, distance field.

Used by ``tests/collision/test_normals.py`` and ``docs/make_normal_figure.py``.
A capsule probe (radius 4 cm, length 6 cm) lies on a surface, sunk 5 mm, at random
places; the surface is voxelised at 1 cm (occupied: cells whose centre is within
half a cell of the surface, the layer a depth camera leaves). The angle between the
contact normal and the true one is measured for the query's raw normal, for
metaball refinements, and for the gradient of a Euclidean distance field of the
cells (:class:`DistanceFieldNormals`, the alternative issue 16 asked to measure).
"""

from __future__ import annotations

from collections.abc import Callable

import coal
import numpy as np
import pinocchio as pin
from scipy.ndimage import distance_transform_edt, map_coordinates

from cbp.collision import MetaballRefiner, OccupancyEnvironment
from cbp.collision.cell_index import CellIndex
from cbp.collision.geometry import LinkShape, PlacedShapes, ShapePlacements
from cbp.robot import FloatArray

__all__ = ["DistanceFieldNormals", "angle_errors", "tilted_plane", "yawed_box"]

CELL = 0.01

#: Draws a point on the true surface and the surface's outward normal there.
Sampler = Callable[[np.random.Generator], tuple[FloatArray, FloatArray]]


def _grid(lo: FloatArray, hi: FloatArray) -> FloatArray:
    axes = [np.arange(a + CELL / 2, b, CELL) for a, b in zip(lo, hi, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def tilted_plane(tilt_deg: float) -> tuple[FloatArray, Sampler]:
    """Cells of a plane through the origin tilted about y; and a normal function."""
    t = np.radians(tilt_deg)
    n = np.array([-np.sin(t), 0.0, np.cos(t)])
    cells = _grid(np.array([-0.3, -0.3, -0.3]), np.array([0.3, 0.3, 0.3]))
    signed = cells.dot(n)
    surface = cells[(signed <= 0) & (signed > -np.sqrt(3) * CELL)]

    def sample(rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
        u, v = rng.uniform(-0.15, 0.15, 2)
        tangent = np.array([np.cos(t), 0.0, np.sin(t)])
        return u * tangent + v * np.array([0.0, 1.0, 0.0]), n

    return surface, sample


def yawed_box(yaw_deg: float) -> tuple[FloatArray, Sampler]:
    """Cells of a 40 cm box's side faces, yawed; and a sampler on the +x' face."""
    R = pin.rpy.rpyToMatrix(0.0, 0.0, np.radians(yaw_deg))
    cells = _grid(np.array([-0.35, -0.35, -0.25]), np.array([0.35, 0.35, 0.25]))
    local = cells.dot(R)  # R^T c
    inside = np.all(np.abs(local) <= 0.2, axis=1)
    outer = np.all(np.abs(local) <= 0.2 - np.sqrt(3) * CELL, axis=1)
    surface = cells[inside & ~outer]

    def sample(rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
        face = rng.integers(2)
        normal_local = (
            np.array([1.0, 0.0, 0.0]) if face == 0 else np.array([0.0, 1.0, 0.0])
        )
        tangent_local = (
            np.array([0.0, 1.0, 0.0]) if face == 0 else np.array([1.0, 0.0, 0.0])
        )
        u, w = rng.uniform(-0.1, 0.1, 2)
        p = 0.2 * normal_local + u * tangent_local + np.array([0.0, 0.0, w])
        return R.dot(p), R.dot(normal_local)

    return surface, sample


class DistanceFieldNormals:
    """Normals from the gradient of a Euclidean distance field of the cells.

    The field (scipy's exact EDT over the cells' box, two cells of border) is
    each grid point's distance to the nearest occupied cell centre; the normal
    at an obstacle witness point is its gradient (central differences,
    interpolated trilinearly) ``offset_cells`` out along the raw normal, where
    the field is the distance to the surface (on the cells it is zero and has
    no gradient). Same interface as :class:`MetaballRefiner`.
    """

    def __init__(self, offset_cells: float) -> None:
        """Evaluate ``offset_cells`` cells out from the witness point."""
        self.offset_cells = offset_cells
        # The last index's field (the index is held: an id could be reused).
        self._index: CellIndex | None = None
        self._field: tuple[list[np.ndarray], FloatArray, float] | None = None

    def _gradient(self, index: CellIndex) -> tuple[list[np.ndarray], FloatArray, float]:
        if self._index is not index or self._field is None:
            cell = index.cell
            lower = index.centres.min(axis=0) - 2 * cell
            ijk = np.rint((index.centres - lower) / cell).astype(int)
            shape = tuple(ijk.max(axis=0) + 3)
            free = np.ones(shape, dtype=bool)
            free[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = False
            field = distance_transform_edt(free, sampling=cell)
            self._index, self._field = index, (np.gradient(field, cell), lower, cell)
        return self._field

    def refine(
        self, index: CellIndex, points: FloatArray, normals: FloatArray
    ) -> FloatArray:
        """The field's unit gradients; a raw normal is kept where it has none."""
        out = np.array(normals, dtype=float).reshape(-1, 3)
        if not len(out):
            return out
        gradient, lower, cell = self._gradient(index)
        at = (points + self.offset_cells * cell * out - lower) / cell
        g = np.stack([map_coordinates(c, at.T, order=1) for c in gradient], axis=1)
        size = np.linalg.norm(g, axis=1)
        ok = size > 1e-9
        out[ok] = g[ok] / size[ok, None]
        return out


def angle_errors(
    surface: FloatArray,
    sample: Sampler,
    refiner: MetaballRefiner | DistanceFieldNormals | None,
    probes: int,
    seed: int = 0,
) -> FloatArray:
    """Angle [deg] between the deepest contact's normal and the true normal."""
    rng = np.random.default_rng(seed)
    env = OccupancyEnvironment(surface, CELL, refiner)  # type: ignore[arg-type]
    capsule = coal.Capsule(0.04, 0.06)
    shape = LinkShape.probe("probe", capsule)
    errors = []
    for _ in range(probes):
        point, normal = sample(rng)
        # Capsule axis along the surface, its side sunk 5 mm.
        axis = np.cross(normal, rng.normal(size=3))
        axis /= np.linalg.norm(axis)
        centre = point + (0.04 - 0.005) * normal
        rotation = pin.Quaternion.FromTwoVectors(
            np.array([0.0, 0.0, 1.0]), axis
        ).matrix()
        placement = pin.SE3(rotation, centre)
        robot = PlacedShapes(
            [shape],
            ShapePlacements([placement]),
            centre[None],
            np.array([0.07]),
            np.full((1, 3), np.inf),
        )
        hits = env.query(robot, 0.0, 1)
        if len(hits):
            cos = float(np.clip(hits.normal[0].dot(normal), -1.0, 1.0))
            errors.append(np.degrees(np.arccos(cos)))
    return np.array(errors)
