# SPDX-License-Identifier: Apache-2.0
"""Aiming the arm's camera: poses that look at a point, and the arm that puts it there.

A look (:mod:`cbp.executors.look`) aims the camera mounted on the arm at what
is unseen: a pose at a point that looks at another (:func:`looking_at`), that
the camera can be carried to through seen free space (:func:`clear_line`),
solved for (:func:`solve_camera`); and the unseen cells that keep a
configuration from being free (:func:`unseen_held`).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from cbp.collision.world import CollisionWorld
from cbp.executors.ik_search import solve_pose
from cbp.perception.kernels import FREE, UNKNOWN
from cbp.perception.occupancy import OccupancyGrid
from cbp.robot import FloatArray, RobotModel
from cbp.run.budget import Budget
from cbp.state import RobotState

__all__ = ["clear_line", "looking_at", "solve_camera", "unseen_held"]

#: The solve's iterations, and how near the pose it must come [m], [rad].
AIM_ITERATIONS = 100
AIM_POSITION, AIM_ANGLE = 0.01, 0.05
#: The solve's damping (added to J J^T's diagonal).
AIM_DAMPING = 1e-4


def solve_camera(
    robot: RobotModel,
    frame: int,
    offset: pin.SE3,
    pose: pin.SE3,
    q: FloatArray,
    budget: Budget,
) -> FloatArray | None:
    """A configuration from ``q`` that puts the camera at ``pose``, or None.

    Damped least squares on the camera's parent ``frame`` (the camera is
    ``offset`` from it); each iteration is charged to ``budget``.
    """
    found, _ = solve_pose(
        robot.model,
        robot.model.createData(),
        frame,
        pose * offset.inverse(),
        q,
        (robot.lower_limits, robot.upper_limits),
        budget,
        iterations=AIM_ITERATIONS,
        tolerances=(AIM_POSITION, AIM_ANGLE),
        damping=AIM_DAMPING,
    )
    return found


def unseen_held(
    world: CollisionWorld, grid: OccupancyGrid, q: FloatArray
) -> FloatArray:
    """The centres of ``grid``'s unseen cells within a cell of the padded arm at ``q``.

    Only the cells in the boxes about the shapes' grown bounding spheres are
    looked at, each once.
    """
    state = RobotState(world.geometry.robot)
    state.update(q)
    geometry = world.geometry
    margin = world.padding - geometry.padding + grid.cell
    shapes = geometry.world_shapes(state)
    reach = shapes.radii + geometry.padding + margin
    dims = np.array(grid.cells.shape)
    lo = np.clip(
        np.floor((shapes.centres.T - reach - grid.lower[:, None]) / grid.cell),
        0,
        dims[:, None],
    )
    hi = np.clip(
        np.floor((shapes.centres.T + reach - grid.lower[:, None]) / grid.cell) + 1,
        0,
        dims[:, None],
    )
    found = [np.zeros(0, dtype=np.intp)]
    for s in range(len(reach)):
        (i0, j0, k0), (i1, j1, k1) = lo[:, s].astype(int), hi[:, s].astype(int)
        i, j, k = np.nonzero(grid.cells[i0:i1, j0:j1, k0:k1] == UNKNOWN)
        found.append(np.ravel_multi_index((i + i0, j + j0, k + k0), grid.cells.shape))
    cells = np.array(
        np.unravel_index(np.unique(np.concatenate(found)), grid.cells.shape)
    )
    unknown = grid.lower + (cells.T + 0.5) * grid.cell
    held = geometry.contains(state, unknown, margin=margin)
    return np.asarray(unknown[held], dtype=float)


def clear_line(a: FloatArray, b: FloatArray, grid: OccupancyGrid) -> bool:
    """Whether the line from ``a`` to ``b`` lies in seen free cells all along."""
    n = max(2, int(np.linalg.norm(b - a) / (0.5 * grid.cell)) + 1)
    line = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    return bool(np.all(grid.state_at(line) == FREE))


def looking_at(eye: FloatArray, centre: FloatArray, rotation: FloatArray) -> pin.SE3:
    """The optical pose at ``eye`` looking at ``centre``, rolled as near ``rotation``.

    Its image's x axis is ``rotation``'s, made square to the new axis.
    """
    z = centre - eye
    z = z / np.linalg.norm(z)
    x = rotation[:, 0] - np.dot(rotation[:, 0], z) * z
    if np.linalg.norm(x) < 1e-6:  # looking along the old x axis: keep its y
        x = np.cross(rotation[:, 1], z)
    x = x / np.linalg.norm(x)
    return pin.SE3(np.column_stack([x, np.cross(z, x), z]), eye)
