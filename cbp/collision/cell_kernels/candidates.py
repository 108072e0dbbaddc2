# SPDX-License-Identifier: Apache-2.0
"""The cells near each robot shape: the closest per shape and group, one pass.

Per shape, the bricks near its box, their cells inside it (a brick's places
at once where it has place bits), each cell's distance and group (a hull's
face, or a capsule's nearest direction), and the closest cell per group
(:func:`candidates`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from cbp.collision.cell_kernels.bricks import (
    ALL_BITS,
    SLOT_BRICK,
    Bricks,
    brick_range,
    lowest_bit,
    place_offsets,
    slots_in_box,
)
from cbp.collision.cell_kernels.measure import (
    CAPSULE,
    VALUE_UNIT,
    Shapes,
    capsule_excess,
    hull_excess,
    shape_frame,
    world_box,
)
from cbp.robot import FloatArray, IntArray

__all__ = ["Candidates", "candidates"]


class Candidates(NamedTuple):
    """Cells near robot shapes.

    The shape (K,), the cell's centre (K, 3), the shape's outward unit normal
    toward it (K, 3), and the distance (K,) [m].
    """

    shape: IntArray
    centre: FloatArray
    outward: FloatArray
    distance: FloatArray

    def head(self, count: int) -> Candidates:
        """The first ``count`` candidates (views)."""
        return Candidates(
            self.shape[:count],
            self.centre[:count],
            self.outward[:count],
            self.distance[:count],
        )


@numba.njit(cache=True, nogil=True)
def candidates(
    bricks: Bricks,
    shapes: Shapes,
    frames: FloatArray,
    half: float,
    directions: FloatArray,
    margin: float,
    exact_within: float,
    out: Candidates,
) -> int:
    """The closest cell per shape and group, within ``margin`` of each shape.

    Per shape (placed by ``frames`` (S, 4, 4)): the bricks near its box, the
    cells inside its box, each cell's distance and group (a hull's face, or the
    capsule direction of ``directions`` closest to the cell), the closest cell
    per group. Hull distances from ``exact_within`` [m] on are lower bounds
    (:mod:`cbp.collision.cell_kernels`). Writes to ``out`` and returns the
    number written.
    """
    centres, start, origin, size, dims, occupied, slots = bricks
    has_slots = len(slots) > 0
    one = np.uint64(1)
    kind, to_frame, lower, upper, capsule = (
        shapes.kind,
        shapes.to_frame,
        shapes.lower,
        shapes.upper,
        shapes.capsule,
    )
    planes, plane_start, faces, values = (
        shapes.planes,
        shapes.plane_start,
        shapes.faces,
        shapes.values,
    )
    grid_origin, grid_dims, grid_start, step = (
        shapes.grid_origin,
        shapes.grid_dims,
        shapes.grid_start,
        shapes.step,
    )
    out_shape, out_centre, out_outward, out_distance = out
    most = len(directions)
    for s in range(len(kind)):
        most = max(most, plane_start[s + 1] - plane_start[s])
    # Per group: the distance, the outward normal and the centre of its
    # closest cell so far (the centre is kept, not read back from a cell index:
    # at the end, those reads were cache misses scattered over the map).
    best = np.full(most, np.inf)
    best_out = np.zeros((most, 6))
    touched = np.empty(most, dtype=np.int64)
    M = np.empty((4, 4))
    # A slot brick's places' centres from its corner, in a shape's frame.
    offsets = np.empty((3, SLOT_BRICK**3))
    cell = size / SLOT_BRICK
    slack = 0.5 * math.sqrt(3.0) * step  # a point's distance to its grid point
    inv_step = 1.0 / step
    count = 0
    for s in range(len(kind)):
        shape_frame(frames, to_frame, s, M)
        r00, r01, r02 = M[0, 0], M[0, 1], M[0, 2]
        r10, r11, r12 = M[1, 0], M[1, 1], M[1, 2]
        r20, r21, r22 = M[2, 0], M[2, 1], M[2, 2]
        tx, ty, tz = M[0, 3], M[1, 3], M[2, 3]
        placed = False  # the places' offsets, for this shape (when needed)
        # How far a brick reaches from its centre along the shape's axes.
        bx_reach = 0.5 * size * (abs(r00) + abs(r10) + abs(r20))
        by_reach = 0.5 * size * (abs(r01) + abs(r11) + abs(r21))
        bz_reach = 0.5 * size * (abs(r02) + abs(r12) + abs(r22))
        # The shape's box, grown by the reach (margin + half a cell).
        lx, ly, lz = lower[s, 0], lower[s, 1], lower[s, 2]
        ux, uy, uz = upper[s, 0], upper[s, 1], upper[s, 2]
        # The bricks that overlap the world box around that box.
        mx, my, mz, wx, wy, wz = world_box(M, lx, ly, lz, ux, uy, uz)
        bx0, bx1 = brick_range(mx - wx, mx + wx, origin[0], size, dims[0])
        by0, by1 = brick_range(my - wy, my + wy, origin[1], size, dims[1])
        bz0, bz1 = brick_range(mz - wz, mz + wz, origin[2], size, dims[2])
        is_capsule = kind[s] == CAPSULE
        radius, half_length = capsule[s, 0], capsule[s, 1]
        # The hull's part of the stacked tables (empty for a capsule).
        hull_planes = planes[plane_start[s] : plane_start[s + 1]]
        hull_faces = faces[grid_start[s] : grid_start[s + 1]]
        hull_values = values[grid_start[s] : grid_start[s + 1]]
        gx, gy, gz = grid_origin[s, 0], grid_origin[s, 1], grid_origin[s, 2]
        ny, nz = grid_dims[s, 1], grid_dims[s, 2]
        # A cell is rejected when its grid point's value (a lower bound, in
        # VALUE_UNIT) shows it further than the margin even after the slack.
        cutoff = (slack + half + margin) / VALUE_UNIT
        exact = exact_within + half
        n_touched = 0
        for bx in range(bx0, bx1 + 1):
            for by in range(by0, by1 + 1):
                column = bx * dims[1] + by
                row = column * dims[2]
                # The column's non-empty bricks in [bz0, bz1], lowest first.
                for word in range(bz0 >> 6, (bz1 >> 6) + 1):
                    bits = occupied[column, word]
                    low = max(bz0 - (word << 6), 0)
                    high = min(bz1 - (word << 6), 63)
                    bits &= ALL_BITS >> np.uint64(63 - high)
                    bits &= ~((np.uint64(1) << np.uint64(low)) - np.uint64(1))
                    while bits:
                        bz = (word << 6) + lowest_bit(bits)
                        bits &= bits - np.uint64(1)
                        b = row + bz
                        # Skip a brick that misses the box along its axes (one
                        # branch: two thirds of the bricks are skipped here).
                        dx = origin[0] + (bx + 0.5) * size - tx
                        dy = origin[1] + (by + 0.5) * size - ty
                        dz = origin[2] + (bz + 0.5) * size - tz
                        x = r00 * dx + r10 * dy + r20 * dz
                        y = r01 * dx + r11 * dy + r21 * dz
                        z = r02 * dx + r12 * dy + r22 * dz
                        if (
                            (x < lx - bx_reach)
                            | (x > ux + bx_reach)
                            | (y < ly - by_reach)
                            | (y > uy + by_reach)
                            | (z < lz - bz_reach)
                            | (z > uz + bz_reach)
                        ):
                            continue
                        if has_slots:
                            # The brick's corner in the shape's frame; its
                            # places from there, all 64 tested at once.
                            dx -= 0.5 * size
                            dy -= 0.5 * size
                            dz -= 0.5 * size
                            corner_x = dx + tx
                            corner_y = dy + ty
                            corner_z = dz + tz
                            x0 = r00 * dx + r10 * dy + r20 * dz
                            y0 = r01 * dx + r11 * dy + r21 * dz
                            z0 = r02 * dx + r12 * dy + r22 * dz
                            held = slots[b]
                            if not placed:
                                place_offsets(M, cell, offsets)
                                placed = True
                            if (
                                (x > lx + bx_reach)
                                & (x < ux - bx_reach)
                                & (y > ly + by_reach)
                                & (y < uy - by_reach)
                                & (z > lz + bz_reach)
                                & (z < uz - bz_reach)
                            ):  # the whole brick is inside the box
                                inside = held
                            else:
                                inside = held & slots_in_box(
                                    x0, y0, z0, offsets, lx, ly, lz, ux, uy, uz
                                )
                            while inside:
                                bit = lowest_bit(inside)
                                inside &= inside - one
                                x = x0 + offsets[0, bit]
                                y = y0 + offsets[1, bit]
                                z = z0 + offsets[2, bit]
                                if is_capsule:
                                    depth, group, ox, oy, oz = capsule_excess(
                                        x,
                                        y,
                                        z,
                                        radius,
                                        half_length,
                                        directions,
                                        half,
                                        margin,
                                    )
                                else:
                                    depth, group = hull_excess(
                                        x,
                                        y,
                                        z,
                                        hull_planes,
                                        hull_faces,
                                        hull_values,
                                        gx,
                                        gy,
                                        gz,
                                        ny,
                                        nz,
                                        inv_step,
                                        cutoff,
                                        exact,
                                    )
                                if depth - half >= margin or depth >= best[group]:
                                    continue
                                if best[group] == np.inf:
                                    touched[n_touched] = group
                                    n_touched += 1
                                best[group] = depth
                                if not is_capsule:
                                    ox = hull_planes[group, 0]
                                    oy = hull_planes[group, 1]
                                    oz = hull_planes[group, 2]
                                best_out[group, 0] = ox
                                best_out[group, 1] = oy
                                best_out[group, 2] = oz
                                # The place's centre: (i, j, k) of bit
                                # (i * 4 + j) * 4 + k, from the brick's corner.
                                i, j, m = bit >> 4, (bit >> 2) & 3, bit & 3
                                best_out[group, 3] = corner_x + (i + 0.5) * cell
                                best_out[group, 4] = corner_y + (j + 0.5) * cell
                                best_out[group, 5] = corner_z + (m + 0.5) * cell
                            continue
                        # Bricks without place bits: each cell read and rotated.
                        # The measuring and keeping below repeat the lines above:
                        # as an inlined helper (which writes the kept arrays, or
                        # takes tuples of them) the pass took 2-3x as long.
                        for k in range(start[b], start[b + 1]):
                            # R^T (c - t): the cell in the shape's frame.
                            dx = centres[k, 0] - tx
                            dy = centres[k, 1] - ty
                            dz = centres[k, 2] - tz
                            x = r00 * dx + r10 * dy + r20 * dz
                            y = r01 * dx + r11 * dy + r21 * dz
                            z = r02 * dx + r12 * dy + r22 * dz
                            # One branch, not six: which cells fall inside is
                            # unpredictable, and mispredictions cost more than this.
                            if not (
                                (x > lx)
                                & (x < ux)
                                & (y > ly)
                                & (y < uy)
                                & (z > lz)
                                & (z < uz)
                            ):
                                continue
                            if is_capsule:
                                depth, group, ox, oy, oz = capsule_excess(
                                    x,
                                    y,
                                    z,
                                    radius,
                                    half_length,
                                    directions,
                                    half,
                                    margin,
                                )
                            else:
                                depth, group = hull_excess(
                                    x,
                                    y,
                                    z,
                                    hull_planes,
                                    hull_faces,
                                    hull_values,
                                    gx,
                                    gy,
                                    gz,
                                    ny,
                                    nz,
                                    inv_step,
                                    cutoff,
                                    exact,
                                )
                            if depth - half >= margin or depth >= best[group]:
                                continue
                            if best[group] == np.inf:
                                touched[n_touched] = group
                                n_touched += 1
                            best[group] = depth
                            if not is_capsule:
                                ox = hull_planes[group, 0]
                                oy = hull_planes[group, 1]
                                oz = hull_planes[group, 2]
                            best_out[group, 0] = ox
                            best_out[group, 1] = oy
                            best_out[group, 2] = oz
                            best_out[group, 3] = centres[k, 0]
                            best_out[group, 4] = centres[k, 1]
                            best_out[group, 5] = centres[k, 2]
        for i in range(n_touched):
            g = touched[i]
            ox, oy, oz = best_out[g, 0], best_out[g, 1], best_out[g, 2]
            out_shape[count] = s
            out_centre[count, 0] = best_out[g, 3]
            out_centre[count, 1] = best_out[g, 4]
            out_centre[count, 2] = best_out[g, 5]
            out_outward[count, 0] = r00 * ox + r01 * oy + r02 * oz
            out_outward[count, 1] = r10 * ox + r11 * oy + r12 * oz
            out_outward[count, 2] = r20 * ox + r21 * oy + r22 * oz
            out_distance[count] = best[g] - half
            count += 1
            best[g] = np.inf
    return count
