# SPDX-License-Identifier: Apache-2.0
"""Accuracy of contact normals against voxelised surfaces: raw coal vs metaball.

Used by ``tests/collision/test_normals.py`` and ``docs/make_normal_figure.py``.
A capsule probe (radius 4 cm, length 6 cm) lies on a surface, sunk 5 mm, at random
places; the surface is voxelised at 1 cm (occupied: cells whose centre is within
half a cell of the surface, the layer a depth camera leaves). The angle between the
contact normal and the true one is measured for coal's raw normal and for metaball
refinements.
"""

from __future__ import annotations

from collections.abc import Callable

import coal
import numpy as np
import pinocchio as pin

from cbp.collision import MetaballRefiner, OccupancyEnvironment
from cbp.collision.geometry import LinkShape, PlacedShapes, ShapePlacements
from cbp.robot import FloatArray

__all__ = ["angle_errors", "tilted_plane", "yawed_box"]

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


def angle_errors(
    surface: FloatArray,
    sample: Sampler,
    refiner: MetaballRefiner | None,
    probes: int,
    seed: int = 0,
) -> FloatArray:
    """Angle [deg] between the deepest contact's normal and the true normal."""
    rng = np.random.default_rng(seed)
    env = OccupancyEnvironment(surface, CELL, refiner)
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
