# SPDX-License-Identifier: Apache-2.0
"""Compiled loops of the occupancy map: seen space, robot volume, obstacle shell.

Each pass visits cells of a dense ``uint8`` grid (:data:`UNKNOWN`, :data:`FREE`,
:data:`OCCUPIED`) a few dozen flops at a time, which numpy could only batch at
the cost of temporaries the size of the grid. They release the GIL, so the map
thread runs beside the control loop.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
import numpy.typing as npt

from cbp.collision.cell_kernels import SLOT_BRICK
from cbp.collision.geometry import inside_any, inside_convex
from cbp.robot import FloatArray, IntArray

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
    passes, cleared by :func:`shell_update`), and ``clear``: True where every
    cell was free at the last :func:`shell_update` (a brick clear and not
    dirty holds free cells only: :func:`mark_seen` skips it); ``stamp``: per
    brick, the frame (``clock[0]``, counted by the grid) in which a cell of
    it last changed state or misses (set by the passes, never cleared).
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
    "carve_shapes",
    "eroded_ranges",
    "frame_changes",
    "insert_readings",
    "mark_seen",
    "merge_entered",
    "occupied_centres",
    "shell_update",
    "tile_windows",
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


@numba.njit(cache=True, nogil=True)
def mark_seen(
    grid: GridArrays,
    box: IntArray,
    ranges: FloatArray,
    near: float,
    misses_to_clear: int,
    windows: IntArray,
    since: int,
    tiles: np.ndarray,
    frame: FrameArrays,
) -> int:
    """Mark the cells a depth image sees through; return how many changed state.

    A cell is seen through when its centre lies in front of the measured surface
    at its pixel by more than a cell (``ranges`` should be the image's range
    eroded over the cell's footprint, so a cell at a depth edge is not taken as
    seen). Unknown cells seen through become free; occupied cells count a miss
    and become free after ``misses_to_clear``. Free cells are skipped: only a
    depth reading (inserted by the caller) makes them occupied, and bricks
    that hold only free cells (``grid.clear`` and not ``grid.dirty``) are
    not visited.

    Args:
        grid: the grid's arrays; cells, misses and dirty bricks updated in place.
        box: index range [i0, i1, j0, j1, k0, k1) to visit (the frustum's box).
        ranges: measured depth along the axis per pixel (H, W): inf sees to
            ``frame.max_range``, -inf (or NaN) says nothing.
        near: cells nearer than this are not marked (the frame's closest
            possible reading) [m].
        misses_to_clear: misses that clear an occupied cell.
        windows: the parts of the image to mark through, (n, 4) pixel ranges
            [c0, c1) x [r0, r1) that do not overlap: only the cells whose
            centre falls in one are visited (each window's own frustum, to
            the far plane, within ``box``). One window of the whole image: the
            frame as a whole.
        since: also the cells of the bricks stamped at or after this frame
            (``grid.stamp``) whose centre falls outside the windows, with
            their range eroded from ``frame.depth`` as :func:`eroded_ranges`
            does (the cells whose state or misses changed since the camera's
            last frame: the others would do what they did then); < 0: none.
        tiles: which tiles of the image the windows cover ((H / tile, W /
            tile), the tile's size from their shapes): the bricks' cells
            there are the windows'.
        frame: the frame: its view (``clip``, ``axis``, ``unproject`` for the
            windows' frusta), its optical centre, ``max_range`` (cells
            farther from the camera are not marked), and its depth buffer and
            limits, for those ranges.
    """
    changed = 0
    h, w = ranges.shape
    span = _open_spans(grid.clear, grid.dirty, grid.brick, grid.cells.shape[2])
    if since >= 0:
        changed += _mark_bricks(grid, box, near, misses_to_clear, since, tiles, frame)
    for n in range(windows.shape[0]):
        c0, c1, r0, r1 = windows[n, 0], windows[n, 1], windows[n, 2], windows[n, 3]
        if c0 == 0 and r0 == 0 and c1 == w and r1 == h:
            changed += _mark_window(
                grid, box, ranges, near, misses_to_clear, windows[n], span, np.inf,
                frame,
            )  # fmt: skip
            continue
        part, deepest = _window_box(windows[n], ranges, grid, box, frame)
        if part[0] < part[1] and part[2] < part[3] and part[4] < part[5]:
            changed += _mark_window(
                grid, part, ranges, near, misses_to_clear, windows[n], span, deepest,
                frame,
            )  # fmt: skip
    return changed


@numba.njit(cache=True, nogil=True)
def _window_ndc(window: IntArray, h: int, w: int) -> tuple[float, float, float, float]:
    """A window's NDC x and y bounds, a pixel wider than its pixels' centres.

    The whole image: [-1, 1] both ways, as wide (the side planes of the frame).
    """
    pixel = 2.0 / min(h, w)  # a pixel of the side planes' rounding
    c0, c1, r0, r1 = window[0], window[1], window[2], window[3]
    if c0 == 0 and r0 == 0 and c1 == w and r1 == h:
        slack = 1.0 + pixel
        return -slack, slack, -slack, slack
    # col = rint((x + 1) w / 2), row = rint(h - 1 - (y + 1) h / 2)
    xa = 2.0 * (c0 - 0.5) / w - 1.0 - pixel
    xb = 2.0 * (c1 - 0.5) / w - 1.0 + pixel
    ya = 2.0 * (h - 0.5 - r1) / h - 1.0 - pixel
    yb = 2.0 * (h - 0.5 - r0) / h - 1.0 + pixel
    return xa, xb, ya, yb


@numba.njit(cache=True, nogil=True)
def _window_box(
    window: IntArray,
    ranges: FloatArray,
    grid: GridArrays,
    box: IntArray,
    frame: FrameArrays,
) -> tuple[IntArray, float]:
    """The cells' index range of a window's frustum, within ``box``; its depth.

    The frustum reaches as deep as the window's farthest range (no cell
    beyond can be seen through), returned too; empty when the window says
    nothing.
    """
    unproject, centre, axis = frame.unproject, frame.camera, frame.axis
    h, w = ranges.shape
    out = np.zeros(6, dtype=np.int64)
    deepest = -np.inf
    for r in range(window[2], window[3]):
        for c in range(window[0], window[1]):
            if ranges[r, c] > deepest:
                deepest = ranges[r, c]
    if not deepest > 0.0:
        return out, deepest
    xa, xb, ya, yb = _window_ndc(window, h, w)
    lo = centre.copy()
    hi = centre.copy()
    for x in (xa, xb):
        for y in (ya, yb):
            # The corner ray's point on the far plane, brought to ``deepest``
            # along the axis (the window's ranges are axial depths).
            p = unproject[:, 0] * x + unproject[:, 1] * y + unproject[:, 2]
            p += unproject[:, 3]
            far = p[:3] / p[3]
            depth = -(axis[0] * far[0] + axis[1] * far[1] + axis[2] * far[2] + axis[3])
            scale = deepest / depth
            for a in range(3):
                v = centre[a] + (far[a] - centre[a]) * scale
                lo[a] = min(lo[a], v)
                hi[a] = max(hi[a], v)
    out = np.empty(6, dtype=np.int64)
    for a in range(3):
        out[2 * a] = max(box[2 * a], math.floor((lo[a] - grid.lower[a]) / grid.cell))
        top = math.floor((hi[a] - grid.lower[a]) / grid.cell) + 1
        out[2 * a + 1] = min(box[2 * a + 1], top)
    return out, deepest


@numba.njit(cache=True, nogil=True)
def _mark_window(
    grid: GridArrays,
    box: IntArray,
    ranges: FloatArray,
    near: float,
    misses_to_clear: int,
    window: IntArray,
    span: IntArray,
    deepest: float,
    frame: FrameArrays,
) -> int:
    """:func:`mark_seen` over one window's cells (``box``: their index range).

    ``deepest``: the window's farthest range [m]: the cells beyond it cannot
    be seen through, and are not visited.

    ``span``: :func:`_open_spans` of the grid at the frame's start (cells only
    become free while marking: the spans stay true).
    """
    lower, cell, brick = grid.lower, grid.cell, grid.brick
    clip, axis = frame.clip, frame.axis
    centre, max_range = frame.camera, frame.max_range
    h, w = ranges.shape
    _, ny, nz = grid.cells.shape
    flat = grid.cells.reshape(-1)
    changed = 0
    limit2 = (max_range - cell) * (max_range - cell)
    xa, xb, ya, yb = _window_ndc(window, h, w)
    col_lo, col_hi, row_lo, row_hi = window[0], window[1], window[2], window[3]
    # A window's frustum as half-spaces a x + b y + c z + d >= 0: in front of
    # the near plane and behind ``deepest``, within its side planes. At each
    # x of the box, only the y its cross-section spans is visited.
    sides = np.empty((6, 4))
    sides[0] = -axis
    sides[0, 3] -= near
    sides[1] = axis
    sides[1, 3] += deepest
    sides[2] = clip[0] - xa * clip[2]
    sides[3] = xb * clip[2] - clip[0]
    sides[4] = clip[1] - ya * clip[2]
    sides[5] = yb * clip[2] - clip[1]
    slim = deepest < np.inf
    for i in range(box[0], box[1]):
        x = lower[0] + (i + 0.5) * cell
        j_lo, j_hi = box[2], box[3]
        if slim:
            y_lo, y_hi = _cross_section(sides, x)
            if not y_lo <= y_hi:
                continue
            j_lo = max(j_lo, math.floor((y_lo - lower[1]) / cell - 0.5) - 1)
            j_hi = min(j_hi, math.ceil((y_hi - lower[1]) / cell - 0.5) + 2)
        for j in range(j_lo, j_hi):
            y = lower[1] + (j + 0.5) * cell
            row = (i * ny + j) * nz
            # Everything but z is the same along the row: per cell, one multiply-add
            # per coordinate.
            d0 = axis[0] * x + axis[1] * y + axis[3]
            x0 = clip[0, 0] * x + clip[0, 1] * y + clip[0, 3]
            y0 = clip[1, 0] * x + clip[1, 1] * y + clip[1, 3]
            w0 = clip[2, 0] * x + clip[2, 1] * y + clip[2, 3]
            r0 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2
            # The column's cells in front of the near plane, within the side
            # planes and in range: an interval of z (each test below is linear
            # in z, the range a quadratic), widened by a cell and a pixel's slack;
            # the cells are still tested one by one.
            lo, hi = -np.inf, np.inf
            lo, hi = _half_line(lo, hi, -d0 - near, -axis[2])
            if deepest < np.inf:  # depth <= deepest
                lo, hi = _half_line(lo, hi, deepest + d0, axis[2])
            # x / w >= xa, x / w <= xb, the same for y (w > 0 in front).
            lo, hi = _half_line(lo, hi, x0 - xa * w0, clip[0, 2] - xa * clip[2, 2])
            lo, hi = _half_line(lo, hi, xb * w0 - x0, xb * clip[2, 2] - clip[0, 2])
            lo, hi = _half_line(lo, hi, y0 - ya * w0, clip[1, 2] - ya * clip[2, 2])
            lo, hi = _half_line(lo, hi, yb * w0 - y0, yb * clip[2, 2] - clip[1, 2])
            left = limit2 - r0
            if left < 0.0:
                continue
            reach = math.sqrt(left)
            lo = max(lo, centre[2] - reach)
            hi = min(hi, centre[2] + reach)
            if not lo <= hi:
                continue
            k_lo = max(box[4], math.floor((lo - lower[2]) / cell - 0.5) - 1)
            k_hi = min(box[5], math.ceil((hi - lower[2]) / cell - 0.5) + 2)
            # Only the cells between the column's first and last bricks that
            # may hold a cell not free.
            k_lo = max(k_lo, span[i // brick, j // brick, 0])
            k_hi = min(k_hi, span[i // brick, j // brick, 1])
            for k in range(k_lo, k_hi):
                c = row + k
                state = flat[c]
                if state == FREE:
                    continue
                z = lower[2] + (k + 0.5) * cell
                depth = -(d0 + axis[2] * z)
                if depth <= near:
                    continue
                cw = w0 + clip[2, 2] * z
                col = int(np.rint(((x0 + clip[0, 2] * z) / cw + 1.0) * w * 0.5))
                if col < col_lo or col >= col_hi:
                    continue
                ndc_y = (y0 + clip[1, 2] * z) / cw
                prow = int(np.rint(h - 1 - (ndc_y + 1.0) * h * 0.5))
                if prow < row_lo or prow >= row_hi:
                    continue
                if not depth < ranges[prow, col] - cell:  # also false for NaN
                    continue
                if r0 + (z - centre[2]) ** 2 > limit2:
                    continue
                changed += _see_cell(grid, c, i, j, k, misses_to_clear)
    return changed


@numba.njit(cache=True, nogil=True)
def _cross_section(sides: FloatArray, x: float) -> tuple[float, float]:
    """The y the region where every row a x + b y + c z + d >= 0 spans at ``x``.

    (The region's cross-section is a convex polygon in y and z: its corners
    are where two of the lines meet; lo > hi when it is empty. The region
    must be bounded.)
    """
    n = sides.shape[0]
    lo, hi = np.inf, -np.inf
    for p in range(n):
        b1, c1, d1 = sides[p, 1], sides[p, 2], sides[p, 0] * x + sides[p, 3]
        for q in range(p + 1, n):
            b2, c2, d2 = sides[q, 1], sides[q, 2], sides[q, 0] * x + sides[q, 3]
            det = b1 * c2 - b2 * c1
            if abs(det) < 1e-12:
                continue
            y = (c1 * d2 - c2 * d1) / det
            z = (b2 * d1 - b1 * d2) / det
            inside = True
            for r in range(n):
                v = sides[r, 0] * x + sides[r, 1] * y + sides[r, 2] * z + sides[r, 3]
                if v < -1e-9:
                    inside = False
                    break
            if inside:
                lo = min(lo, y)
                hi = max(hi, y)
    return lo, hi


@numba.njit(cache=True, nogil=True, inline="always")
def _see_cell(grid: GridArrays, c: int, i: int, j: int, k: int, to_clear: int) -> int:
    """A cell (not free; flat index ``c``, grid index i, j, k) seen through.

    Unknown: free. Occupied: a miss, free at ``to_clear`` misses. Its brick
    is stamped with the grid's clock, and made dirty if it changed state.
    Returns 1 if it changed state, else 0.
    """
    flat = grid.cells.reshape(-1)
    missed = grid.misses.reshape(-1)
    b = grid.brick
    grid.stamp[i // b, j // b, k // b] = grid.clock[0]
    if flat[c] == UNKNOWN:
        flat[c] = FREE
        grid.dirty[i // b, j // b, k // b] = True
        return 1
    m = missed[c] + 1
    if m >= to_clear:
        flat[c] = FREE
        missed[c] = 0
        grid.dirty[i // b, j // b, k // b] = True
        return 1
    missed[c] = m
    return 0


@numba.njit(cache=True, nogil=True)
def _mark_bricks(
    grid: GridArrays,
    box: IntArray,
    near: float,
    misses_to_clear: int,
    since: int,
    tiles: np.ndarray,
    frame: FrameArrays,
) -> int:
    """:func:`mark_seen` over the cells of the bricks stamped ``since`` on.

    Those whose centre falls in a tile of ``tiles`` are left to the windows.
    """
    lower, cell, brick, stamp = grid.lower, grid.cell, grid.brick, grid.stamp
    clip, axis = frame.clip, frame.axis
    centre, max_range = frame.camera, frame.max_range
    depth, spread = frame.depth, frame.spread
    h, w = depth.shape
    tile = -(-h // tiles.shape[0])
    _, ny, nz = grid.cells.shape
    flat = grid.cells.reshape(-1)
    limit2 = (max_range - cell) * (max_range - cell)
    changed = 0
    bx, by, bz = stamp.shape
    for p in range(box[0] // brick, min((box[1] + brick - 1) // brick, bx)):
        for q in range(box[2] // brick, min((box[3] + brick - 1) // brick, by)):
            for r in range(box[4] // brick, min((box[5] + brick - 1) // brick, bz)):
                if stamp[p, q, r] < since:
                    continue
                for i in range(max(p * brick, box[0]), min((p + 1) * brick, box[1])):
                    x = lower[0] + (i + 0.5) * cell
                    for j in range(
                        max(q * brick, box[2]), min((q + 1) * brick, box[3])
                    ):
                        y = lower[1] + (j + 0.5) * cell
                        row = (i * ny + j) * nz
                        for k in range(
                            max(r * brick, box[4]), min((r + 1) * brick, box[5])
                        ):
                            c = row + k
                            if flat[c] == FREE:
                                continue
                            z = lower[2] + (k + 0.5) * cell
                            d = -(axis[0] * x + axis[1] * y + axis[3] + axis[2] * z)
                            if d <= near:
                                continue
                            cw = clip[2, 0] * x + clip[2, 1] * y + clip[2, 3]
                            cw += clip[2, 2] * z
                            cx = clip[0, 0] * x + clip[0, 1] * y + clip[0, 3]
                            cx += clip[0, 2] * z
                            col = int(np.rint((cx / cw + 1.0) * w * 0.5))
                            if col < 0 or col >= w:
                                continue
                            cy = clip[1, 0] * x + clip[1, 1] * y + clip[1, 3]
                            cy += clip[1, 2] * z
                            prow = int(np.rint(h - 1 - (cy / cw + 1.0) * h * 0.5))
                            if prow < 0 or prow >= h:
                                continue
                            if tiles[prow // tile, col // tile]:
                                continue
                            least = _eroded_at(
                                depth, prow, col, spread[0], spread[1],
                                frame.nearest, frame.far_plane, frame.far_buffer,
                            )  # fmt: skip
                            if not d < least - cell:
                                continue
                            rx, ry = (x - centre[0]) ** 2, (y - centre[1]) ** 2
                            if rx + ry + (z - centre[2]) ** 2 > limit2:
                                continue
                            changed += _see_cell(grid, c, i, j, k, misses_to_clear)
    return changed


@numba.njit(cache=True, nogil=True, inline="always")
def _eroded_at(
    depth: FloatArray,
    r: int,
    c: int,
    near: float,
    far: float,
    nearest: float,
    far_plane: float,
    far_buffer: float,
) -> float:
    """:func:`eroded_ranges` at one pixel (the least over its 3 x 3 neighbours)."""
    h, w = depth.shape
    least = np.nan
    for rr in range(max(r - 1, 0), min(r + 2, h)):
        for cc in range(max(c - 1, 0), min(c + 2, w)):
            z = depth[rr, cc]
            if np.isnan(z):
                continue
            if not _holds_reading(z, nearest, far_buffer):
                v = -np.inf
            elif z >= far_plane:
                v = far
            else:
                v = far * near / (far - (far - near) * z)
            least = _least(least, v)
    return -np.inf if np.isnan(least) else least


@numba.njit(cache=True, nogil=True)
def _open_spans(clear: np.ndarray, dirty: np.ndarray, brick: int, nz: int) -> IntArray:
    """Per column of bricks, the cells from its first to its last brick not clear.

    (bx, by, 2): the first such cell's k and one past the last's; a column
    whose bricks are all clear and not dirty (only free cells) has an empty
    span.
    """
    bx, by, bz = clear.shape
    span = np.zeros((bx, by, 2), dtype=np.int64)
    for p in range(bx):
        for q in range(by):
            first, last = bz, -1
            for r in range(bz):
                if dirty[p, q, r] or not clear[p, q, r]:
                    first = min(first, r)
                    last = r
            if last >= 0:
                span[p, q, 0] = first * brick
                span[p, q, 1] = min((last + 1) * brick, nz)
    return span


@numba.njit(cache=True, nogil=True)
def _half_line(lo: float, hi: float, a: float, b: float) -> tuple[float, float]:
    """The interval [lo, hi] cut to where a + b z >= 0."""
    if b > 0.0:
        lo = max(lo, -a / b)
    elif b < 0.0:
        hi = min(hi, -a / b)
    elif a < 0.0:
        return 1.0, 0.0  # empty
    return lo, hi


@numba.njit(cache=True, nogil=True)
def carve_shapes(
    grid: GridArrays,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    boxes: FloatArray,
    grow: float,
) -> int:
    """Mark unknown cells whose centre is inside a grown shape free; return count.

    The robot was there, so the space is free (occupied cells are kept: an
    obstacle seen inside the robot's padding is real). The shapes as
    :class:`~cbp.collision.geometry.WorldShapes` gives them; ``boxes``
    (shapes, 6) holds each grown shape's world bounding box (lower corner,
    upper corner). Cells and dirty bricks (``grid``) are updated in place.
    """
    lower, cell, dirty, brick = grid.lower, grid.cell, grid.dirty, grid.brick
    nx, ny, nz = grid.cells.shape
    flat = grid.cells.reshape(-1)
    size = (nx, ny, nz)
    lo = np.empty(3, dtype=np.int64)
    hi = np.empty(3, dtype=np.int64)
    changed = 0
    for s in range(boxes.shape[0]):
        for a in range(3):
            lo[a] = max(int(np.ceil((boxes[s, a] - lower[a]) / cell - 0.5)), 0)
            top = int(np.floor((boxes[s, 3 + a] - lower[a]) / cell - 0.5)) + 1
            hi[a] = min(top, size[a])
        first, last = plane_start[s], plane_start[s + 1]
        cx, cy, cz = centres[s, 0], centres[s, 1], centres[s, 2]
        reach2 = (radii[s] + grow) ** 2
        for i in range(lo[0], hi[0]):
            x = lower[0] + (i + 0.5) * cell
            for j in range(lo[1], hi[1]):
                y = lower[1] + (j + 0.5) * cell
                row = (i * ny + j) * nz
                for k in range(lo[2], hi[2]):
                    if flat[row + k] != UNKNOWN:
                        continue
                    z = lower[2] + (k + 0.5) * cell
                    if (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2 > reach2:
                        continue
                    if inside_convex(x, y, z, planes, first, last, grow):
                        flat[row + k] = FREE
                        dirty[i // brick, j // brick, k // brick] = True
                        grid.stamp[i // brick, j // brick, k // brick] = grid.clock[0]
                        changed += 1
    return changed


@numba.njit(cache=True, nogil=True)
def shell_update(
    grid: GridArrays,
    blocked: np.ndarray,
    unknown_blocks: bool,
    old_centres: FloatArray,
    old_start: IntArray,
    old_slots: SlotArray,
) -> tuple[FloatArray, IntArray, SlotArray]:
    """The obstacle cells next to open space, brick by brick, redone where changed.

    A cell is blocked when occupied, or unknown and ``unknown_blocks``; it is in
    the shell when one of its six neighbours inside the grid is not blocked.
    Only the shell can be the cell closest to a robot shape that stands in open
    space, so only the shell is indexed: a solid block of unknown space costs
    its surface, not its volume.

    Only the bricks marked ``dirty`` (a cell in them changed state since the
    last update) have their ``blocked`` mask recomputed, and only they and
    their six neighbouring bricks (whose face cells border them) are scanned for
    the shell; every other brick's run is copied from ``old_centres``. A map
    whose view does not change costs a copy of its shell. Bricks of
    :data:`~cbp.collision.cell_kernels.SLOT_BRICK` cells also get their
    occupied places as bits (:attr:`~cbp.collision.cell_kernels.Bricks.slots`:
    the scan visits a brick's cells in place order), so the index of the
    shell does not read its centres again.

    Args:
        grid: the grid's arrays: its dirty bricks are cleared here, and each
            one's ``clear`` flag (all its cells free) set anew.
        blocked: the blocked mask (nx, ny, nz), kept up to date in place.
        unknown_blocks: unknown cells are obstacles.
        old_centres: the last update's shell (its result), brick by brick.
        old_start: its runs (bricks + 1,).
        old_slots: its places as bits (bricks,), empty for other bricks.

    Returns:
        (centres (N, 3) in brick order, start (bricks + 1,), slots (bricks,)
        or empty): brick b's cells are ``centres[start[b]:start[b + 1]]``,
        bricks numbered in C order.
    """
    cells, dirty, clear = grid.cells, grid.dirty, grid.clear
    lower, cell, brick = grid.lower, grid.cell, grid.brick
    nx, ny, nz = cells.shape
    bx, by, bz = dirty.shape
    redo = np.zeros((bx, by, bz), dtype=np.bool_)
    for p in range(bx):
        for q in range(by):
            for r in range(bz):
                if not dirty[p, q, r]:
                    continue
                free = True
                for i in range(p * brick, min((p + 1) * brick, nx)):
                    for j in range(q * brick, min((q + 1) * brick, ny)):
                        for k in range(r * brick, min((r + 1) * brick, nz)):
                            v = cells[i, j, k]
                            free = free and v == FREE
                            blocked[i, j, k] = v == OCCUPIED or (
                                unknown_blocks and v == UNKNOWN
                            )
                clear[p, q, r] = free
                redo[p, q, r] = True
                if p > 0:
                    redo[p - 1, q, r] = True
                if p + 1 < bx:
                    redo[p + 1, q, r] = True
                if q > 0:
                    redo[p, q - 1, r] = True
                if q + 1 < by:
                    redo[p, q + 1, r] = True
                if r > 0:
                    redo[p, q, r - 1] = True
                if r + 1 < bz:
                    redo[p, q, r + 1] = True
                dirty[p, q, r] = False
    # The redone bricks' shell cells first, each brick's run in ``fresh``
    # (its start in ``first``); then each brick's run from there or the old
    # shell, into an array of the exact size (the snapshot's own).
    n_bricks = bx * by * bz
    with_slots = brick == SLOT_BRICK
    slots = np.zeros(n_bricks if with_slots else 0, dtype=np.uint64)
    first = np.zeros(n_bricks + 1, dtype=np.int64)
    fresh = np.empty((1024, 3))
    count = 0
    total = 0
    b = 0
    for p in range(bx):
        for q in range(by):
            for r in range(bz):
                first[b] = count
                if not redo[p, q, r]:
                    total += old_start[b + 1] - old_start[b]
                    if with_slots:
                        slots[b] = old_slots[b]
                    b += 1
                    continue
                if len(fresh) - count < brick**3:  # room for a brick's cells
                    grown = np.empty((2 * len(fresh) + brick**3, 3))
                    grown[:count] = fresh[:count]
                    fresh = grown
                bits = np.uint64(0)
                for i in range(p * brick, min((p + 1) * brick, nx)):
                    for j in range(q * brick, min((q + 1) * brick, ny)):
                        for k in range(r * brick, min((r + 1) * brick, nz)):
                            if blocked[i, j, k] and (
                                (k > 0 and not blocked[i, j, k - 1])
                                or (k + 1 < nz and not blocked[i, j, k + 1])
                                or (j > 0 and not blocked[i, j - 1, k])
                                or (j + 1 < ny and not blocked[i, j + 1, k])
                                or (i > 0 and not blocked[i - 1, j, k])
                                or (i + 1 < nx and not blocked[i + 1, j, k])
                            ):
                                fresh[count, 0] = lower[0] + (i + 0.5) * cell
                                fresh[count, 1] = lower[1] + (j + 0.5) * cell
                                fresh[count, 2] = lower[2] + (k + 0.5) * cell
                                count += 1
                                if with_slots:  # (i, j, k) in the brick
                                    a = (i % brick * brick + j % brick) * brick
                                    place = a + k % brick
                                    bits |= np.uint64(1) << np.uint64(place)
                total += count - first[b]
                if with_slots:
                    slots[b] = bits
                b += 1
    first[n_bricks] = count
    centres = np.empty((total, 3))
    start = np.zeros(n_bricks + 1, dtype=np.int64)
    n = 0
    b = 0
    for p in range(bx):
        for q in range(by):
            for r in range(bz):
                if redo[p, q, r]:
                    run = first[b + 1] - first[b]
                    centres[n : n + run] = fresh[first[b] : first[b + 1]]
                else:
                    run = old_start[b + 1] - old_start[b]
                    centres[n : n + run] = old_centres[old_start[b] : old_start[b + 1]]
                n += run
                b += 1
                start[b] = n
    return centres, start, slots


@numba.njit(cache=True, nogil=True, inline="always")
def _holds_reading(z: float, nearest: float, far_buffer: float) -> bool:
    """A depth buffer value is a reading (as DepthFrame.valid tells)."""
    return bool(np.isfinite(z) and z >= nearest and z <= far_buffer)


@numba.njit(cache=True, nogil=True)
def eroded_ranges(
    depth: FloatArray,
    near: float,
    far: float,
    nearest: float,
    far_plane: float,
    far_buffer: float,
) -> FloatArray:
    """Each pixel's range along the axis, the least over its 3 x 3 neighbours [m].

    What :meth:`~cbp.perception.frame.DepthFrame.ranges` gives, with a pixel
    holding no reading at -inf (it says nothing) and background at ``far``
    (seen to the far plane), eroded over 3 x 3 pixels (edges repeat the border
    pixel): a cell at a depth edge or on a grazing surface spans several pixels
    and is seen through only in front of all of them. ``nearest``,
    ``far_plane`` and ``far_buffer`` are depth buffer values: the minimum
    range, where the far plane starts, and the largest valid value.

    A pixel whose value is NaN (the sensor gave no return: the far side of a
    depth edge, a dropout; :mod:`cbp.sim.depth_noise`) is left out of the
    least: its surface lies beyond its nearer neighbours (an edge) or is as
    unknown as a dropout on a continuous surface, so along its own ray it is
    seen through as far as its neighbours, and a pixel with only NaN around
    it says nothing (-inf). Any other value that is no reading (nearer than
    the minimum range, say) stops its neighbours too: something is there.
    """
    h, w = depth.shape
    metric = np.empty((h, w))
    for r in range(h):
        for c in range(w):
            z = depth[r, c]
            if np.isnan(z):
                metric[r, c] = np.nan
            elif not _holds_reading(z, nearest, far_buffer):
                metric[r, c] = -np.inf
            elif z >= far_plane:
                metric[r, c] = far
            else:
                metric[r, c] = far * near / (far - (far - near) * z)
    # The least over 3 x 3 pixels, in two passes of three: along each row (NaN
    # where all three are NaN), then down each column of those.
    across = np.empty((h, w))
    for r in range(h):
        for c in range(w):
            least = np.nan
            for cc in range(max(c - 1, 0), min(c + 2, w)):
                least = _least(least, metric[r, cc])
            across[r, c] = least
    out = np.empty((h, w))
    for r in range(h):
        r0, r1 = max(r - 1, 0), min(r + 2, h)
        for c in range(w):
            least = np.nan
            for rr in range(r0, r1):
                least = _least(least, across[rr, c])
            out[r, c] = -np.inf if np.isnan(least) else least
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _axial(z: float, nearest: float, far_plane: float, far_buffer: float,
           near: float, far: float) -> float:  # fmt: skip
    """A depth buffer value along the axis [m]; inf: the far plane, -inf: none."""
    if not _holds_reading(z, nearest, far_buffer):
        return -np.inf
    if z >= far_plane:
        return np.inf
    return far * near / (far - (far - near) * z)


@numba.njit(cache=True, nogil=True)
def frame_changes(
    frame: FrameArrays,
    kept: KeptPixels,
    whole: bool,
    tile: int,
    slack: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Which pixels of a frame to integrate, and which tiles to see through.

    A pixel changed when its reading differs from the one last integrated
    (``kept.range``) by more than sqrt(2) times the spread of the camera's
    noise at its depth (``frame.spread``: two readings of a still surface
    differ by less, but for one in a few hundred at three sigmas) plus
    ``slack`` [m] (with noise only; no noise: by anything), or it gained or
    lost a reading or the far plane. A pixel
    without a return (NaN) says nothing and is left as it was. A pixel is
    integrated when it changed, or its last reading was taken for the robot
    or came nearer than the space seen free (``kept.cell``, ``kept.hold``);
    ``kept.range`` takes its reading then. A tile (``tile`` pixels a side) is
    seen through when a pixel in it or beside it (the range is eroded over 3 x
    3 pixels) changed.

    ``whole``: every pixel and tile (the frame as a whole).

    Returns (integrate (H, W) bool, tiles (ceil(H / tile), ceil(W / tile)) bool).
    """
    depth, spread = frame.depth, frame.spread
    nearest, far_plane, far_buffer = frame.nearest, frame.far_plane, frame.far_buffer
    near, far = spread[0], spread[1]
    h, w = depth.shape
    todo = np.zeros((h, w), dtype=np.bool_)
    tiles = np.zeros(((h + tile - 1) // tile, (w + tile - 1) // tile), dtype=np.bool_)
    if whole:
        tiles[:] = True
    rng, cells, hold = kept.range, kept.cell, kept.hold
    margin = slack if spread[2] > 0.0 or spread[3] > 0.0 else 0.0
    for r in range(h):
        for c in range(w):
            z = depth[r, c]
            if np.isnan(z):
                todo[r, c] = whole
                continue
            now = _axial(z, nearest, far_plane, far_buffer, near, far)
            before = rng[r, c]
            if np.isfinite(now) and np.isfinite(before):
                allowed = spread[2] + spread[3] * (now - spread[4]) ** 2
                changed = abs(now - before) > margin + math.sqrt(2.0) * allowed
            else:  # gained or lost a reading, or the far plane (NaN: never kept)
                changed = now != before
            if changed and not whole:
                for rr in range(max(r - 1, 0), min(r + 2, h)):
                    for cc in range(max(c - 1, 0), min(c + 2, w)):
                        tiles[rr // tile, cc // tile] = True
            if whole or changed or cells[r, c] <= KEPT_ROBOT or hold[r, c]:
                todo[r, c] = True
                rng[r, c] = now
    return todo, tiles


@numba.njit(cache=True, nogil=True)
def tile_windows(tiles: np.ndarray, tile: int, h: int, w: int) -> IntArray:
    """The marked tiles as windows (n, 4) of pixels [c0, c1) x [r0, r1).

    Runs of marked tiles along a row of tiles, each merged with the run of
    the rows below that spans the same columns; clipped to the image.
    """
    th, tw = tiles.shape
    out = np.empty((th * tw, 4), dtype=np.int64)
    n = 0
    for tr in range(th):
        tc = 0
        while tc < tw:
            if not tiles[tr, tc]:
                tc += 1
                continue
            start = tc
            while tc < tw and tiles[tr, tc]:
                tc += 1
            c0, c1 = start * tile, min(tc * tile, w)
            r0, r1 = tr * tile, min((tr + 1) * tile, h)
            merged = False
            for m in range(n):  # the same columns, ending where this starts
                if out[m, 0] == c0 and out[m, 1] == c1 and out[m, 3] == r0:
                    out[m, 3] = r1
                    merged = True
                    break
            if not merged:
                out[n, 0], out[n, 1], out[n, 2], out[n, 3] = c0, c1, r0, r1
                n += 1
    return out[:n].copy()


@numba.njit(cache=True, nogil=True)
def eroded_ranges_in(
    depth: FloatArray,
    near: float,
    far: float,
    nearest: float,
    far_plane: float,
    far_buffer: float,
    windows: IntArray,
) -> FloatArray:
    """:func:`eroded_ranges` in the ``windows`` (n, 4) only; -inf elsewhere.

    The same values there (the least over 3 x 3 pixels, NaN left out).
    """
    h, w = depth.shape
    out = np.full((h, w), -np.inf)
    for n in range(windows.shape[0]):
        for r in range(windows[n, 2], windows[n, 3]):
            for c in range(windows[n, 0], windows[n, 1]):
                out[r, c] = _eroded_at(
                    depth, r, c, near, far, nearest, far_plane, far_buffer
                )
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _least(a: float, b: float) -> float:
    """The lesser of two values, NaN counting as none (NaN if both are)."""
    if np.isnan(a):
        return b
    if np.isnan(b):
        return a
    return min(a, b)


@numba.njit(cache=True, nogil=True)
def insert_readings(
    frame: FrameArrays,
    robot: RobotShapes,
    grid: GridArrays,
    moved: PixelHistory,
    t: float,
    hold: float,
    entered: np.ndarray,
    todo: np.ndarray,
    kept: KeptPixels,
    motion: FloatArray,
) -> tuple[int, int, int, int, int]:
    """Mark the cells depth readings fall in occupied; count valid, robot, inserted.

    Each pixel of ``frame`` that holds a reading nearer than the far plane is
    unprojected (as :meth:`~cbp.perception.frame.DepthFrame.points` does),
    dropped when farther than ``max_range`` from the camera or within
    ``robot.reach[s]`` of a robot shape s grown by how far the camera's noise
    spreads the reading along its ray (``frame.spread``), and its cell made
    occupied with no misses. One pass, one call: the map thread takes the GIL
    once per frame for it, not once per array operation. A reading outside
    the box around every shape's grown bounding sphere is not tested against
    the shapes (it cannot be in one).

    Space that comes to be hidden (``moved``, the camera's pixel history; empty
    arrays: not tracked): where a pixel's reading, not the robot, is more than
    two cells (and sqrt(2) times the spread, what two noisy readings of one
    surface differ by) nearer than the range the camera saw free along it,
    something came between, and the free cells behind the reading are made
    unknown, up to the robot's shapes grown by ``robot.held[s]`` or that range
    (:func:`_hide_ray`). It is done again at every frame while the reading
    moves (by more than half a cell and the spread) and for ``hold`` seconds
    after (``t``: the frame's time); then the nearer range is what the camera
    sees free along the pixel.

    The cells those nearer readings fall in are where something entered space
    the camera saw free: a moving obstacle's leading surface. Their flat grid
    indices (``(i * ny + j) * nz + k``) are written to ``entered``, as many as
    it holds.

    Only the pixels ``todo`` marks (:func:`frame_changes`) are integrated so;
    each other pixel holding a reading keeps the cell its last integrated
    reading made occupied (``kept.cell``) occupied with no misses, as that
    reading would. ``kept`` takes what each integrated pixel did.

    A reading of a pixel last taken for the robot is tested against the same
    shape first, without its face planes while a bound shows it inside:
    ``motion`` (S, 2) holds how far each shape's sphere centre moved since the
    camera's last frame [m] and by what angle it turned [rad] (inf: not
    known), so a point at r from the centre moved at most the first plus
    the second times r; with how far the reading moved along its ray, that
    bounds how much nearer to the faces it can be (the planes' normals are
    unit vectors). The pixel is taken for the robot exactly when the
    planes would say so.

    Returns (pixels holding a reading, readings taken for the robot, readings
    inserted or kept, cells hidden, cells entered).
    """
    depth, u, camera, spread = frame.depth, frame.unproject, frame.camera, frame.spread
    nearest, far_plane, far_buffer = frame.nearest, frame.far_plane, frame.far_buffer
    max_range = frame.max_range
    planes, plane_start = robot.planes, robot.plane_start
    columns = np.ascontiguousarray(planes.T)  # the planes a few at a time
    centres, radii, reach = robot.centres, robot.radii, robot.reach
    cells, misses, lower, cell = grid.cells, grid.misses, grid.lower, grid.cell
    h, w = depth.shape
    nx, ny, nz = cells.shape
    valid = 0
    on_robot = 0
    inserted = 0
    hidden = 0
    n_entered = 0
    seen_to, last, moved_at = moved
    track = seen_to.shape[0] == h
    gap = 2.0 * cell
    noisy = spread[2] > 0.0 or spread[3] > 0.0
    # The box around the shapes' grown spheres (a millimetre wider: the sphere
    # test rounds differently), grown by each reading's spread below.
    box = np.empty(6)
    box[:3] = np.inf
    box[3:] = -np.inf
    for s in range(radii.size):
        r = radii[s] + reach[s] + 1e-3
        for a in range(3):
            box[a] = min(box[a], centres[s, a] - r)
            box[3 + a] = max(box[3 + a], centres[s, a] + r)
    flat_cells = cells.reshape(-1)
    flat_misses = misses.reshape(-1)
    for r in range(h):
        y = 2.0 * (h - 1 - r) / h - 1.0
        for c in range(w):
            z = depth[r, c]
            if not _holds_reading(z, nearest, far_buffer):
                if todo[r, c] and not np.isnan(z):
                    kept.cell[r, c] = KEPT_NONE
                continue
            valid += 1
            if not todo[r, c]:  # as the reading last integrated left it
                f = kept.cell[r, c]
                if f >= 0:
                    inserted += 1
                    if flat_cells[f] != OCCUPIED or flat_misses[f] != 0:
                        i, rest = divmod(f, ny * nz)
                        j, k = divmod(rest, nz)
                        _occupy(grid, i, j, k)
                continue
            was = kept.cell[r, c]
            kept.cell[r, c] = KEPT_NONE
            kept.hold[r, c] = False
            if z >= far_plane:
                if track:  # seen free to the far plane
                    seen_to[r, c] = max_range
                    last[r, c] = max_range
                continue
            x = 2.0 * c / w - 1.0
            zn = 2.0 * z - 1.0
            ww = u[3, 0] * x + u[3, 1] * y + u[3, 2] * zn + u[3, 3]
            px = (u[0, 0] * x + u[0, 1] * y + u[0, 2] * zn + u[0, 3]) / ww
            py = (u[1, 0] * x + u[1, 1] * y + u[1, 2] * zn + u[1, 3]) / ww
            pz = (u[2, 0] * x + u[2, 1] * y + u[2, 2] * zn + u[2, 3]) / ww
            dx, dy, dz = px - camera[0], py - camera[1], pz - camera[2]
            distance = math.sqrt(dx * dx + dy * dy + dz * dz)
            if distance > max_range:
                if track:
                    seen_to[r, c] = max_range
                    last[r, c] = max_range
                continue
            extra = 0.0
            if noisy:  # the spread at this depth, along the ray
                axial = (
                    spread[1] * spread[0] / (spread[1] - (spread[1] - spread[0]) * z)
                )
                extra = spread[2] + spread[3] * (axial - spread[4]) ** 2
                extra *= distance / axial
            near_robot = (
                box[0] - extra <= px <= box[3] + extra
                and box[1] - extra <= py <= box[4] + extra
                and box[2] - extra <= pz <= box[5] + extra
            )
            shape = KEPT_ROBOT - was  # the shape it was in, or < 0
            bound = np.inf
            if near_robot and 0 <= shape < radii.size:  # that shape first
                ex, ey = px - centres[shape, 0], py - centres[shape, 1]
                ez = pz - centres[shape, 2]
                moved = motion[shape, 0] + motion[shape, 1] * math.sqrt(
                    ex * ex + ey * ey + ez * ez
                )
                shift = abs(distance - kept.distance[r, c]) + moved
                bound = kept.bound[r, c] + shift * (1.0 + 1e-6)
                if not bound <= extra:  # not known inside: its planes
                    bound = _beyond(
                        px,
                        py,
                        pz,
                        columns,
                        plane_start[shape],
                        plane_start[shape + 1],
                        reach[shape] + extra,
                    )
                    bound -= reach[shape]  # fmt: skip
                    if not bound <= extra:
                        shape = -1
            else:
                shape = -1
            if near_robot and shape < 0:
                shape, bound = _inside_which(
                    px, py, pz, columns, plane_start, centres, radii, reach, extra
                )
            if shape >= 0:
                on_robot += 1
                kept.cell[r, c] = KEPT_ROBOT - shape
                kept.distance[r, c] = distance
                kept.bound[r, c] = bound
                if track:  # seen free up to the robot; it hides nothing new
                    seen_to[r, c] = max(seen_to[r, c], distance)
                continue
            came = False
            if track:
                if abs(distance - last[r, c]) > 0.5 * cell + extra:
                    moved_at[r, c] = t
                last[r, c] = distance
                # Two readings of a still surface differ by sqrt(2) sigma.
                if distance < seen_to[r, c] - gap - math.sqrt(2.0) * extra:
                    came = True
                    kept.hold[r, c] = True
                    hidden += _hide_ray(
                        camera,
                        dx / distance,
                        dy / distance,
                        dz / distance,
                        distance + cell,
                        seen_to[r, c],
                        robot,
                        grid,
                    )
                    if t - moved_at[r, c] >= hold:  # it stopped: its shadow now
                        seen_to[r, c] = distance
                else:
                    seen_to[r, c] = distance
            i = math.floor((px - lower[0]) / cell)
            j = math.floor((py - lower[1]) / cell)
            k = math.floor((pz - lower[2]) / cell)
            if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
                continue
            inserted += 1
            kept.cell[r, c] = (i * ny + j) * nz + k
            # Entered: the reading came nearer and its cell was not occupied
            # (a surface uncovered by the robot, mapped by another pixel, is not).
            came = came and cells[i, j, k] != OCCUPIED
            if cells[i, j, k] != OCCUPIED or misses[i, j, k] != 0:
                _occupy(grid, i, j, k)
            if came and n_entered < entered.shape[0]:
                entered[n_entered] = (i * ny + j) * nz + k
                n_entered += 1
    return valid, on_robot, inserted, hidden, n_entered


@numba.njit(cache=True, nogil=True, inline="always")
def _occupy(grid: GridArrays, i: int, j: int, k: int) -> None:
    """Make a cell occupied with no misses; its brick stamped (and dirty)."""
    b = grid.brick
    grid.misses[i, j, k] = 0
    grid.stamp[i // b, j // b, k // b] = grid.clock[0]
    if grid.cells[i, j, k] != OCCUPIED:
        grid.cells[i, j, k] = OCCUPIED
        grid.dirty[i // b, j // b, k // b] = True


@numba.njit(cache=True, nogil=True, inline="always")
def _inside_which(
    x: float,
    y: float,
    z: float,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    grow: FloatArray,
    extra: float,
) -> tuple[int, float]:
    """The first shape s holding (x, y, z) grown by ``grow[s] + extra``, or -1.

    :func:`~cbp.collision.geometry.inside_any`, telling which, and how far
    beyond its face planes the point lies, less ``grow[s]`` (inf: none);
    ``planes`` (4, P) as :func:`_beyond` takes them.
    """
    for s in range(radii.size):
        grown = grow[s] + extra
        dx, dy, dz = x - centres[s, 0], y - centres[s, 1], z - centres[s, 2]
        reach = radii[s] + grown
        if dx * dx + dy * dy + dz * dz > reach * reach:
            continue
        beyond = _beyond(x, y, z, planes, plane_start[s], plane_start[s + 1], grown)
        if beyond <= grown:
            return s, beyond - grow[s]
    return -1, np.inf


@numba.njit(cache=True, nogil=True, fastmath=True)
def _beyond(
    x: float,
    y: float,
    z: float,
    planes: FloatArray,
    start: int,
    stop: int,
    grow: float,
) -> float:
    """How far (x, y, z) lies beyond the planes [start, stop): the largest n . x - d.

    Stops at the first run of 32 planes with one it lies more than ``grow``
    beyond (that run's largest value): inside the planes grown by ``grow``
    when at most ``grow``, as :func:`~cbp.collision.geometry.inside_convex`
    tells. ``planes`` (4, P): the planes' columns (n, d) as rows, so that a
    run's values are taken a few at a time (the planes are finite).
    """
    nx, ny, nz, d = planes[0], planes[1], planes[2], planes[3]
    most = -np.inf
    p = start
    while p < stop:
        end = min(p + 32, stop)
        run = -np.inf
        for q in range(p, end):
            run = max(run, nx[q] * x + ny[q] * y + nz[q] * z - d[q])
        if run > grow:
            return run
        most = max(most, run)
        p = end
    return most


@numba.njit(cache=True, nogil=True)
def _hide_ray(
    camera: FloatArray,
    ux: float,
    uy: float,
    uz: float,
    start: float,
    stop: float,
    robot: RobotShapes,
    grid: GridArrays,
) -> int:
    """Make the free cells along a ray unknown, from ``start`` to ``stop`` [m].

    In half-cell steps from ``camera`` along the unit direction (ux, uy, uz);
    the march ends where it enters a robot shape grown by ``robot.held`` (what
    lies behind the robot was hidden by it, not by the new surface). Returns
    the cells made unknown.
    """
    cells, lower, cell = grid.cells, grid.lower, grid.cell
    nx, ny, nz = cells.shape
    step = 0.5 * cell
    hidden = 0
    s = start
    while s < stop:
        x = camera[0] + ux * s
        y = camera[1] + uy * s
        z = camera[2] + uz * s
        s += step
        if inside_any(
            x,
            y,
            z,
            robot.planes,
            robot.plane_start,
            robot.centres,
            robot.radii,
            robot.held,
        ):
            break
        i = math.floor((x - lower[0]) / cell)
        j = math.floor((y - lower[1]) / cell)
        k = math.floor((z - lower[2]) / cell)
        if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
            continue
        if cells[i, j, k] == FREE:
            cells[i, j, k] = UNKNOWN
            grid.dirty[i // grid.brick, j // grid.brick, k // grid.brick] = True
            grid.stamp[i // grid.brick, j // grid.brick, k // grid.brick] = grid.clock[
                0
            ]
            hidden += 1
    return hidden


@numba.njit(cache=True, nogil=True)
def merge_entered(
    flat: IntArray,
    when: FloatArray,
    entered: IntArray,
    t: float,
    oldest: float,
) -> tuple[IntArray, FloatArray]:
    """The cells entered lately, with the cells a frame entered at ``t`` added.

    ``flat`` and ``when``: the kept cells' flat indices and when each was last
    entered [s]; those entered before ``oldest`` are dropped, and those in
    ``entered`` (the frame's cells, repeats allowed) move to the end, sorted
    and once each, entered at ``t``. One call: the map thread does not wait for
    the interpreter lock between array operations.
    """
    new = np.sort(entered)
    unique = 0
    for a in range(new.size):
        if unique == 0 or new[a] != new[unique - 1]:
            new[unique] = new[a]
            unique += 1
    new = new[:unique]
    out_flat = np.empty(flat.size + unique, dtype=np.int64)
    out_when = np.empty(flat.size + unique)
    n = 0
    for a in range(flat.size):
        if not when[a] >= oldest:
            continue
        b = np.searchsorted(new, flat[a])
        if b < unique and new[b] == flat[a]:
            continue
        out_flat[n] = flat[a]
        out_when[n] = when[a]
        n += 1
    out_flat[n : n + unique] = new
    out_when[n : n + unique] = t
    n += unique
    return out_flat[:n].copy(), out_when[:n].copy()


@numba.njit(cache=True, nogil=True)
def occupied_centres(
    flat: IntArray,
    when: FloatArray,
    oldest: float,
    cells: np.ndarray,
    lower: FloatArray,
    cell: float,
) -> FloatArray:
    """Centres (N, 3) [m] of the cells of ``flat`` entered since ``oldest``, occupied.

    In the order of ``flat``; ``cells``: the grid's states.
    """
    _, ny, nz = cells.shape
    states = cells.reshape(-1)
    out = np.empty((flat.size, 3))
    n = 0
    for a in range(flat.size):
        f = flat[a]
        if not when[a] >= oldest or states[f] != OCCUPIED:
            continue
        i, rest = divmod(f, ny * nz)
        j, k = divmod(rest, nz)
        out[n, 0] = lower[0] + (i + 0.5) * cell
        out[n, 1] = lower[1] + (j + 0.5) * cell
        out[n, 2] = lower[2] + (k + 0.5) * cell
        n += 1
    return out[:n].copy()
