# SPDX-License-Identifier: Apache-2.0
"""The cells a depth frame sees through: unknown ones become free, occupied miss.

The cells of the frame's frustum (of each window of changed pixels, to its
farthest range) are projected into the image; a cell in front of its pixel's
eroded range by more than a cell is seen through (:func:`mark_seen`). Only
the z interval of each column the frustum spans is visited, and only the
bricks that may hold a cell not free.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cbp.perception.kernels.arrays import FREE, UNKNOWN, FrameArrays, GridArrays
from cbp.perception.kernels.pixels import eroded_at
from cbp.robot import FloatArray, IntArray

__all__ = ["mark_seen"]


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
            their range eroded from ``frame.depth`` as
            :func:`~cbp.perception.kernels.eroded_ranges` does (the cells
            whose state or misses changed since the camera's last frame: the
            others would do what they did then); < 0: none.
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
                            least = eroded_at(
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
