# SPDX-License-Identifier: Apache-2.0
"""Compiled loops of the occupancy map: seen space, robot volume, obstacle shell.

Each pass visits cells of a dense ``uint8`` grid (:data:`UNKNOWN`, :data:`FREE`,
:data:`OCCUPIED`) a few dozen flops at a time, which numpy could only batch at
the cost of temporaries the size of the grid. They release the GIL, so the map
thread runs beside the control loop.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cbp.collision.geometry import inside_any, inside_convex
from cbp.robot import FloatArray, IntArray

PixelHistory = tuple[FloatArray, FloatArray, FloatArray]
"""A camera's pixels: the range seen free along each, the last reading's range
[m], and when it last moved [s], each (H, W); (0, 0) arrays: not tracked."""

__all__ = [
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "PixelHistory",
    "carve_shapes",
    "eroded_ranges",
    "insert_readings",
    "mark_seen",
    "shell_update",
]

UNKNOWN = 0
"""Never seen, never held by the robot."""
FREE = 1
"""Seen through, or held by the robot (see ``OccupancyGrid.carve_robot``)."""
OCCUPIED = 2
"""A depth reading fell in it (and no later frame saw through it often enough)."""


@numba.njit(cache=True, nogil=True)
def mark_seen(
    grid: np.ndarray,
    misses: np.ndarray,
    lower: FloatArray,
    cell: float,
    box: IntArray,
    clip: FloatArray,
    axis: FloatArray,
    centre: FloatArray,
    ranges: FloatArray,
    near: float,
    max_range: float,
    misses_to_clear: int,
    dirty: np.ndarray,
    brick: int,
) -> int:
    """Mark the cells a depth image sees through; return how many changed state.

    A cell is seen through when its centre lies in front of the measured surface
    at its pixel by more than a cell (``ranges`` should be the image's range
    eroded over the cell's footprint, so a cell at a depth edge is not taken as
    seen). Unknown cells seen through become free; occupied cells count a miss
    and become free after ``misses_to_clear``. Free cells are skipped: only a
    depth reading (inserted by the caller) makes them occupied.

    Args:
        grid: cell states (nx, ny, nz), updated in place.
        misses: misses of occupied cells, updated in place.
        lower: the grid's lower corner [m].
        cell: cell size [m].
        box: index range [i0, i1, j0, j1, k0, k1) to visit (the frustum's box).
        clip: the first, second and fourth rows of P V (3, 4): world to clip x,
            y and w.
        axis: the third row of V (4,): -depth along the optical axis.
        centre: the optical centre [m].
        ranges: measured depth along the axis per pixel (H, W): inf sees to
            ``max_range``, -inf (or NaN) says nothing.
        near: cells nearer than this are not marked (the frame's closest
            possible reading) [m].
        max_range: cells farther from the camera are not marked [m].
        misses_to_clear: misses that clear an occupied cell.
        dirty: per brick of ``brick`` cells a side, True where a cell changed
            state (updated in place, for :func:`shell_update`).
        brick: cells per brick side.
    """
    h, w = ranges.shape
    _, ny, nz = grid.shape
    flat = grid.reshape(-1)
    missed = misses.reshape(-1)
    changed = 0
    limit2 = (max_range - cell) * (max_range - cell)
    slack = 1.0 + 2.0 / min(h, w)  # a pixel of the side planes' rounding
    for i in range(box[0], box[1]):
        x = lower[0] + (i + 0.5) * cell
        for j in range(box[2], box[3]):
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
            for a, b in (
                (x0, clip[0, 2]),
                (-x0, -clip[0, 2]),
                (y0, clip[1, 2]),
                (-y0, -clip[1, 2]),
            ):
                lo, hi = _half_line(lo, hi, slack * w0 + a, slack * clip[2, 2] + b)
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
                if col < 0 or col >= w:
                    continue
                ndc_y = (y0 + clip[1, 2] * z) / cw
                prow = int(np.rint(h - 1 - (ndc_y + 1.0) * h * 0.5))
                if prow < 0 or prow >= h:
                    continue
                if not depth < ranges[prow, col] - cell:  # also false for NaN
                    continue
                if r0 + (z - centre[2]) ** 2 > limit2:
                    continue
                if state == UNKNOWN:
                    flat[c] = FREE
                    dirty[i // brick, j // brick, k // brick] = True
                    changed += 1
                else:
                    m = missed[c] + 1
                    if m >= misses_to_clear:
                        flat[c] = FREE
                        missed[c] = 0
                        dirty[i // brick, j // brick, k // brick] = True
                        changed += 1
                    else:
                        missed[c] = m
    return changed


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
    grid: np.ndarray,
    lower: FloatArray,
    cell: float,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    boxes: FloatArray,
    grow: float,
    dirty: np.ndarray,
    brick: int,
) -> int:
    """Mark unknown cells whose centre is inside a grown shape free; return count.

    The robot was there, so the space is free (occupied cells are kept: an
    obstacle seen inside the robot's padding is real). The shapes as
    :class:`~cbp.collision.geometry.WorldShapes` gives them; ``boxes``
    (shapes, 6) holds each grown shape's world bounding box (lower corner,
    upper corner). ``dirty`` and ``brick`` as in :func:`mark_seen`.
    """
    nx, ny, nz = grid.shape
    flat = grid.reshape(-1)
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
                        changed += 1
    return changed


@numba.njit(cache=True, nogil=True)
def shell_update(
    grid: np.ndarray,
    blocked: np.ndarray,
    dirty: np.ndarray,
    lower: FloatArray,
    cell: float,
    brick: int,
    unknown_blocks: bool,
    old_centres: FloatArray,
    old_start: IntArray,
) -> tuple[FloatArray, IntArray]:
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
    whose view does not change costs a copy of its shell.

    Args:
        grid: cell states (nx, ny, nz).
        blocked: the blocked mask (nx, ny, nz), kept up to date in place.
        dirty: per brick (bx, by, bz), True where cells changed; cleared here.
        lower: the grid's lower corner [m].
        cell: cell size [m].
        brick: cells per brick side.
        unknown_blocks: unknown cells are obstacles.
        old_centres: the last update's shell (its result), brick by brick.
        old_start: its runs (bricks + 1,).

    Returns:
        (centres (N, 3) in brick order, start (bricks + 1,)): brick b's cells
        are ``centres[start[b]:start[b + 1]]``, bricks numbered in C order.
    """
    nx, ny, nz = grid.shape
    bx, by, bz = dirty.shape
    redo = np.zeros((bx, by, bz), dtype=np.bool_)
    for p in range(bx):
        for q in range(by):
            for r in range(bz):
                if not dirty[p, q, r]:
                    continue
                for i in range(p * brick, min((p + 1) * brick, nx)):
                    for j in range(q * brick, min((q + 1) * brick, ny)):
                        for k in range(r * brick, min((r + 1) * brick, nz)):
                            v = grid[i, j, k]
                            blocked[i, j, k] = v == OCCUPIED or (
                                unknown_blocks and v == UNKNOWN
                            )
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
    centres = np.empty((len(old_centres) + 1024, 3))
    start = np.zeros(bx * by * bz + 1, dtype=np.int64)
    count = 0
    b = 0
    for p in range(bx):
        for q in range(by):
            for r in range(bz):
                if len(centres) - count < brick**3:  # room for a brick's cells
                    grown = np.empty((2 * len(centres), 3))
                    grown[:count] = centres[:count]
                    centres = grown
                if not redo[p, q, r]:
                    first, last = old_start[b], old_start[b + 1]
                    if len(centres) - count < last - first:
                        grown = np.empty((2 * len(centres) + last - first, 3))
                        grown[:count] = centres[:count]
                        centres = grown
                    centres[count : count + last - first] = old_centres[first:last]
                    count += last - first
                else:
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
                                    centres[count, 0] = lower[0] + (i + 0.5) * cell
                                    centres[count, 1] = lower[1] + (j + 0.5) * cell
                                    centres[count, 2] = lower[2] + (k + 0.5) * cell
                                    count += 1
                b += 1
                start[b] = count
    return centres[:count].copy(), start


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
def _least(a: float, b: float) -> float:
    """The lesser of two values, NaN counting as none (NaN if both are)."""
    if np.isnan(a):
        return b
    if np.isnan(b):
        return a
    return min(a, b)


@numba.njit(cache=True, nogil=True)
def insert_readings(
    depth: FloatArray,
    unproject: FloatArray,
    nearest: float,
    far_plane: float,
    far_buffer: float,
    camera: FloatArray,
    max_range: float,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    reach: FloatArray,
    grid: np.ndarray,
    misses: np.ndarray,
    lower: FloatArray,
    cell: float,
    dirty: np.ndarray,
    brick: int,
    moved: PixelHistory,
    t: float,
    hold: float,
    held: FloatArray,
    spread: FloatArray,
    entered: np.ndarray,
) -> tuple[int, int, int, int, int]:
    """Mark the cells depth readings fall in occupied; count valid, robot, inserted.

    Each pixel that holds a reading nearer than the far plane is unprojected
    (``unproject``: the inverse of projection times view, as
    :meth:`~cbp.perception.frame.DepthFrame.points` does), dropped when
    farther than ``max_range`` from ``camera`` or within ``reach[s]`` of a
    robot shape s (the shapes as :class:`~cbp.collision.geometry.WorldShapes`
    gives them; no shapes: no robot) grown by how far the camera's noise
    spreads the reading along its ray (``spread``: the projection's near and
    far planes [m] and c0, c2, z0 [m]: c0 + c2 (z - z0)^2 along the axis at
    depth z, so many sigmas of the noise; c0 and c2 0: no noise), and its cell made
    occupied with no
    misses. One pass, one call: the map thread takes the GIL once per frame
    for it, not once per array operation. ``dirty`` and ``brick`` as in
    :func:`mark_seen`.

    Space that comes to be hidden (``moved``, the camera's pixel history; empty
    arrays: not tracked): where a pixel's reading, not the robot, is more than
    two cells (and sqrt(2) times the spread, what two noisy readings of one
    surface differ by) nearer than the range the camera saw free along it,
    something came between, and the free cells behind the reading are made unknown, up
    to the robot's shapes grown by ``held[s]`` or that range
    (:func:`_hide_ray`). It is done again at every frame while the reading
    moves (by more than half a cell and the spread) and for ``hold`` seconds
    after (``t``: the frame's time); then the
    nearer range is what the camera sees free along the pixel.

    The cells those nearer readings fall in are where something entered space
    the camera saw free: a moving obstacle's leading surface. Their flat grid
    indices (``(i * ny + j) * nz + k``) are written to ``entered``, as many as
    it holds.

    Returns (pixels holding a reading, readings taken for the robot, readings
    inserted, cells hidden, cells entered).
    """
    h, w = depth.shape
    nx, ny, nz = grid.shape
    u = unproject
    valid = 0
    robot = 0
    inserted = 0
    hidden = 0
    n_entered = 0
    seen_to, last, moved_at = moved
    track = seen_to.shape[0] == h
    gap = 2.0 * cell
    noisy = spread[2] > 0.0 or spread[3] > 0.0
    for r in range(h):
        y = 2.0 * (h - 1 - r) / h - 1.0
        for c in range(w):
            z = depth[r, c]
            if not _holds_reading(z, nearest, far_buffer):
                continue
            valid += 1
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
            if inside_any(
                px, py, pz, planes, plane_start, centres, radii, reach, extra
            ):
                robot += 1
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
                    hidden += _hide_ray(
                        camera,
                        dx / distance,
                        dy / distance,
                        dz / distance,
                        distance + cell,
                        seen_to[r, c],
                        planes,
                        plane_start,
                        centres,
                        radii,
                        held,
                        grid,
                        lower,
                        cell,
                        dirty,
                        brick,
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
            misses[i, j, k] = 0
            if grid[i, j, k] != OCCUPIED:
                grid[i, j, k] = OCCUPIED
                dirty[i // brick, j // brick, k // brick] = True
            if came and n_entered < entered.shape[0]:
                entered[n_entered] = (i * ny + j) * nz + k
                n_entered += 1
    return valid, robot, inserted, hidden, n_entered


@numba.njit(cache=True, nogil=True)
def _hide_ray(
    camera: FloatArray,
    ux: float,
    uy: float,
    uz: float,
    start: float,
    stop: float,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    held: FloatArray,
    grid: np.ndarray,
    lower: FloatArray,
    cell: float,
    dirty: np.ndarray,
    brick: int,
) -> int:
    """Make the free cells along a ray unknown, from ``start`` to ``stop`` [m].

    In half-cell steps from ``camera`` along the unit direction (ux, uy, uz);
    the march ends where it enters a robot shape grown by ``held`` (what lies
    behind the robot was hidden by it, not by the new surface). Returns the
    cells made unknown.
    """
    nx, ny, nz = grid.shape
    step = 0.5 * cell
    hidden = 0
    s = start
    while s < stop:
        x = camera[0] + ux * s
        y = camera[1] + uy * s
        z = camera[2] + uz * s
        s += step
        if inside_any(x, y, z, planes, plane_start, centres, radii, held):
            break
        i = math.floor((x - lower[0]) / cell)
        j = math.floor((y - lower[1]) / cell)
        k = math.floor((z - lower[2]) / cell)
        if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
            continue
        if grid[i, j, k] == FREE:
            grid[i, j, k] = UNKNOWN
            dirty[i // brick, j // brick, k // brick] = True
            hidden += 1
    return hidden
