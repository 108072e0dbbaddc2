# SPDX-License-Identifier: Apache-2.0
"""What the map's passes share: the cells' states and the arrays they read.

A grid's cells are ``uint8`` states (:data:`UNKNOWN`, :data:`FREE`,
:data:`OCCUPIED`); the passes take a grid (:class:`GridArrays`), a depth frame
(:class:`FrameArrays`), the robot's shapes (:class:`RobotShapes`) and a
camera's pixels (:class:`PixelHistory`, :class:`KeptPixels`) as named tuples
of arrays, built once and updated in place.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from cbp.robot import FloatArray, IntArray

__all__ = [
    "FREE",
    "KEPT_NONE",
    "KEPT_ROBOT",
    "OCCUPIED",
    "UNKNOWN",
    "FrameArrays",
    "GridArrays",
    "KeptPixels",
    "PixelHistory",
    "RobotShapes",
    "SlotArray",
]

UNKNOWN = 0
"""Never seen, never held by the robot."""
FREE = 1
"""Seen through, or held by the robot (see ``OccupancyGrid.carve_robot``)."""
OCCUPIED = 2
"""A depth reading fell in it (and no later frame saw through it often enough)."""

KEPT_NONE = -1
"""A pixel whose reading made no cell occupied (:class:`KeptPixels`)."""
KEPT_ROBOT = -2
"""A pixel whose reading was taken for the robot: this minus the shape it was
in (:class:`KeptPixels`)."""

SlotArray = npt.NDArray[np.uint64]
"""Each brick's occupied places as bits (``Bricks.slots`` of
:mod:`cbp.collision.cell_kernels`)."""


class PixelHistory(NamedTuple):
    """A camera's pixels, each (H, W); (0, 0) arrays: not tracked.

    The range seen free along each [m], the last reading's range [m], and when
    it last moved [s].
    """

    seen_to: FloatArray
    last: FloatArray
    moved_at: FloatArray


class KeptPixels(NamedTuple):
    """What a camera's pixels last gave the map, each (H, W).

    ``range``: the reading last integrated, along the axis [m] (``inf``: the
    far plane, ``-inf``: no reading, NaN: none integrated yet); ``cell``:
    what it did, the flat index (``(i * ny + j) * nz + k``) of the cell it
    made occupied, or :data:`KEPT_NONE` (nothing), :data:`KEPT_ROBOT` - s
    (taken for the robot: inside its shape s); ``hold``: it came nearer than
    the space seen free (hidden space: integrated again at every frame).
    """

    range: FloatArray
    cell: IntArray
    hold: np.ndarray
    distance: FloatArray
    bound: FloatArray


class GridArrays(NamedTuple):
    """A grid's arrays as the passes update them (built once per grid).

    The cell states (nx, ny, nz) (:data:`UNKNOWN`, :data:`FREE`,
    :data:`OCCUPIED`) and the misses of occupied cells, both updated in place;
    the grid's lower corner [m] and cell size [m]; per brick of ``brick``
    cells a side, ``dirty``: True where a cell changed state (set by the
    passes, cleared by :func:`~cbp.perception.kernels.shell_update`), and
    ``clear``: True where every cell was free at the last
    :func:`~cbp.perception.kernels.shell_update` (a brick clear and not dirty
    holds free cells only: :func:`~cbp.perception.kernels.mark_seen` skips
    it); ``stamp``: per brick, the frame (``clock[0]``, counted by the grid)
    in which a cell of it last changed state or misses (set by the passes,
    never cleared).
    """

    cells: np.ndarray
    misses: np.ndarray
    lower: FloatArray
    cell: float
    dirty: np.ndarray
    brick: int
    clear: np.ndarray
    stamp: IntArray
    clock: IntArray


class RobotShapes(NamedTuple):
    """The robot's shapes placed for one frame, as the self-filter takes them.

    The shapes as :class:`~cbp.collision.geometry.WorldShapes` gives them
    (face planes (P, 4) and each shape's first plane (S + 1,), bounding sphere
    centres (S, 3) and radii (S,) [m]), how far around each shape a reading
    is the robot's (``reach`` (S,) [m]), and how far beyond each shape
    hidden space stops (``held`` (S,) [m]). No shapes: no robot.
    """

    planes: FloatArray
    plane_start: IntArray
    centres: FloatArray
    radii: FloatArray
    reach: FloatArray
    held: FloatArray


class FrameArrays(NamedTuple):
    """One depth frame as :func:`insert_readings` and :func:`mark_seen` read it.

    The depth buffer (H, W) and ``unproject``, the inverse of projection times
    view (4, 4), as :meth:`~cbp.perception.frame.DepthFrame.points` uses it;
    ``clip``, the first, second and fourth rows of projection times view (3,
    4): world to clip x, y and w; ``axis``, the third row of the view (4,):
    -depth along the optical axis; depth buffer values ``nearest`` (the
    minimum range), ``far_plane`` (from there on: nothing seen) and
    ``far_buffer`` (the largest valid); the optical centre ``camera`` [m];
    ``max_range`` [m], beyond which readings are dropped (and cells not seen
    through); and ``spread``, how far the camera's noise spreads a reading:
    the projection's near and far planes [m] and c0, c2, z0 [m], c0 + c2 (z -
    z0)^2 along the axis at depth z (so many sigmas of the noise; c0 and c2 0:
    no noise).
    """

    depth: FloatArray
    unproject: FloatArray
    clip: FloatArray
    axis: FloatArray
    nearest: float
    far_plane: float
    far_buffer: float
    camera: FloatArray
    max_range: float
    spread: FloatArray
