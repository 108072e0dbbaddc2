# SPDX-License-Identifier: Apache-2.0
"""Contacts from the cells near the shapes: reduced per shape, normals refined.

The candidates (:mod:`cbp.collision.cell_kernels.candidates`) become contacts,
up to a few per shape spread over directions (:func:`reduce_cells`), their
normals re-estimated from the cells around them when asked
(:func:`metaball_normals`); :func:`cell_contacts` does the whole query in one
call.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from cbp.collision.cell_kernels.bricks import Bricks, brick_range
from cbp.collision.cell_kernels.candidates import Candidates, candidates
from cbp.collision.cell_kernels.measure import Shapes
from cbp.robot import FloatArray, IntArray

__all__ = [
    "Contacts",
    "cell_contacts",
    "cell_contacts_flat",
    "cell_hits",
    "metaball_normals",
    "reduce_cells",
    "spread_contacts",
]


class Contacts(NamedTuple):
    """Contacts with cells.

    The shape (K,), the point on its surface (K, 3), the point on the cell
    (K, 3), the unit normal from the cell toward the shape (K, 3), and the
    distance (K,) [m].
    """

    shape: IntArray
    robot: FloatArray
    obstacle: FloatArray
    normal: FloatArray
    distance: FloatArray

    @classmethod
    def room(cls, count: int) -> Contacts:
        """Uninitialised arrays for ``count`` contacts (a kernel's output)."""
        return cls(
            np.empty(count, dtype=np.intp),
            np.empty((count, 3)),
            np.empty((count, 3)),
            np.empty((count, 3)),
            np.empty(count),
        )

    @classmethod
    def packed(cls, shape: IntArray, floats: FloatArray, count: int) -> Contacts:
        """The first ``count`` contacts of :func:`cell_contacts_flat`'s output.

        Views of ``shape`` (K,) and of ``floats`` (4, K, 3): robot points,
        obstacle points and normals, then distances in ``floats[3, :, 0]``.
        """
        return cls(
            shape[:count],
            floats[0, :count],
            floats[1, :count],
            floats[2, :count],
            floats[3, :count, 0],
        )

    def head(self, count: int) -> Contacts:
        """The first ``count`` contacts (views)."""
        return Contacts(
            self.shape[:count],
            self.robot[:count],
            self.obstacle[:count],
            self.normal[:count],
            self.distance[:count],
        )


@numba.njit(cache=True, nogil=True)
def metaball_normals(
    bricks: Bricks, at: FloatArray, radius: float, normals: FloatArray
) -> None:
    """Replace ``normals`` by -grad F / |grad F| at ``at`` where F has a gradient.

    F is the metaball field of :class:`~cbp.collision.map_environment.MetaballRefiner`
    over the cells within ``radius`` of each point.
    """
    centres, start, origin, size, dims = bricks[:5]
    r2 = radius * radius
    ranges = np.empty((3, 2), dtype=np.int64)
    for i in range(len(at)):
        for a in range(3):
            ranges[a, 0], ranges[a, 1] = brick_range(
                at[i, a] - radius, at[i, a] + radius, origin[a], size, dims[a]
            )
        gx = gy = gz = 0.0
        for bx in range(ranges[0, 0], ranges[0, 1] + 1):
            for by in range(ranges[1, 0], ranges[1, 1] + 1):
                row = (bx * dims[1] + by) * dims[2]
                for bz in range(ranges[2, 0], ranges[2, 1] + 1):
                    b = row + bz
                    for k in range(start[b], start[b + 1]):
                        dx = at[i, 0] - centres[k, 0]
                        dy = at[i, 1] - centres[k, 1]
                        dz = at[i, 2] - centres[k, 2]
                        d2 = dx * dx + dy * dy + dz * dz
                        if d2 <= r2:
                            s = 1.0 - d2 / r2
                            w = s * s  # dF/dx = -6 s^2 (x - c) / R^2: scale later
                            gx += w * dx
                            gy += w * dy
                            gz += w * dz
        norm = math.sqrt(gx * gx + gy * gy + gz * gz)
        if norm > 1e-12:  # the normal is -grad F, along +sum s^2 (x - c)
            normals[i, 0] = gx / norm
            normals[i, 1] = gy / norm
            normals[i, 2] = gz / norm


@numba.njit(cache=True, nogil=True)
def spread_contacts(
    order: IntArray,
    shape: IntArray,
    normal: FloatArray,
    point: FloatArray,
    per_shape: int,
    cos_max: float,
    spacing2: float,
    keep: IntArray,
) -> int:
    """Keep up to ``per_shape`` contacts per shape, spread over directions.

    Contacts are visited in ``order`` (by shape, then distance); one is kept unless
    its shape has ``per_shape`` already, or a kept one of its shape has a normal
    within the angle (cosine above ``cos_max``) and a point within the spacing
    (squared distance below ``spacing2``). Writes the kept indices to ``keep``
    and returns their number.
    """
    n = 0
    first = 0  # the current shape's first entry in ``keep``
    current = -1
    for k in order:
        if shape[k] != current:
            current = shape[k]
            first = n
        if n - first >= per_shape:
            continue
        similar = False
        for i in range(first, n):
            m = keep[i]
            dot = (
                normal[k, 0] * normal[m, 0]
                + normal[k, 1] * normal[m, 1]
                + normal[k, 2] * normal[m, 2]
            )
            if dot > cos_max:
                dx = point[k, 0] - point[m, 0]
                dy = point[k, 1] - point[m, 1]
                dz = point[k, 2] - point[m, 2]
                if dx * dx + dy * dy + dz * dz < spacing2:
                    similar = True
                    break
        if not similar:
            keep[n] = k
            n += 1
    return n


def cell_hits(
    found: Candidates, half: float, per_shape: int, cos_max: float, spacing2: float
) -> Contacts:
    """Contacts from :func:`candidates`' cells, reduced per shape.

    Per shape (the candidates come shape by shape), the closest cell first, then
    the next closest unless a kept one has a normal within the angle (cosine
    above ``cos_max``) and a robot point within the spacing (squared distance
    below ``spacing2``), up to ``per_shape``: :func:`spread_contacts` on cells.

    Returns:
        The contacts by shape and then distance: the point on the shape's surface,
        the point on the cell toward the shape, the unit normal from the cell
        toward the shape.
    """
    n = len(found.shape)
    out = Contacts.room(n)
    count = reduce_cells(found, n, half, per_shape, cos_max, spacing2, out)
    return out.head(count)


#: Up to this many candidates of a shape are sorted by insertion (no allocation).
_FEW = 32


@numba.njit(cache=True, nogil=True)
def reduce_cells(
    found: Candidates,
    n: int,
    half: float,
    per_shape: int,
    cos_max: float,
    spacing2: float,
    out: Contacts,
) -> int:
    """The loop of :func:`cell_hits` over the first ``n`` candidates.

    Writes to ``out``, returns the count.
    """
    shape, centre, outward, distance = found
    out_shape, robot, obstacle, normal, out_distance = out
    keep = np.empty(max(per_shape, 1), dtype=np.int64)
    order = np.empty(n, dtype=np.int64)
    count = 0
    start = 0
    while start < n:
        end = start
        while end < n and shape[end] == shape[start]:
            end += 1
        # By distance, stable as np.lexsort (equal distances keep the
        # candidates' order); a shape has a few, sorted without allocating.
        if end - start > _FEW:
            order[: end - start] = (
                np.argsort(distance[start:end], kind="mergesort") + start
            )
        else:
            for k in range(start, end):
                i = k - start
                while i > 0 and distance[order[i - 1]] > distance[k]:
                    order[i] = order[i - 1]
                    i -= 1
                order[i] = k
        kept = 0
        for k in order[: end - start]:
            if kept >= per_shape:
                break
            reach_k = distance[k] + half
            similar = False
            for i in range(kept):
                m = keep[i]
                dot = (
                    outward[k, 0] * outward[m, 0]
                    + outward[k, 1] * outward[m, 1]
                    + outward[k, 2] * outward[m, 2]
                )
                if dot > cos_max:
                    reach_m = distance[m] + half
                    d2 = 0.0
                    for a in range(3):
                        d = (centre[k, a] - reach_k * outward[k, a]) - (
                            centre[m, a] - reach_m * outward[m, a]
                        )
                        d2 += d * d
                    if d2 < spacing2:
                        similar = True
                        break
            if similar:
                continue
            keep[kept] = k
            kept += 1
            out_shape[count] = shape[k]
            for a in range(3):
                robot[count, a] = centre[k, a] - reach_k * outward[k, a]
                obstacle[count, a] = centre[k, a] - half * outward[k, a]
                normal[count, a] = -outward[k, a]
            out_distance[count] = distance[k]
            count += 1
        start = end
    return count


@numba.njit(cache=True, nogil=True)
def cell_contacts(
    bricks: Bricks,
    shapes: Shapes,
    frames: FloatArray,
    half: float,
    directions: FloatArray,
    margin: float,
    exact_within: float,
    per_shape: int,
    cos_max: float,
    spacing2: float,
    refine_radius: float,
    refine_offset: float,
    capacity: int,
    out: Contacts,
) -> int:
    """The shapes' contacts with the cells, in one call.

    :func:`candidates` (room for ``capacity``: one per shape and group), those
    reduced into ``out`` as :func:`cell_hits` does (room for ``per_shape`` per
    shape), and, when ``refine_radius`` > 0, their normals re-estimated as
    :class:`~cbp.collision.map_environment.MetaballRefiner` does: the field of
    the cells within ``refine_radius`` [m] of the obstacle point moved
    ``refine_offset`` [m] along the normal (:func:`metaball_normals`). Returns
    the number of contacts written to ``out``.
    """
    found = Candidates(
        np.empty(capacity, dtype=np.intp),
        np.empty((capacity, 3)),
        np.empty((capacity, 3)),
        np.empty(capacity),
    )
    n = candidates(
        bricks, shapes, frames, half, directions, margin, exact_within, found
    )
    count = reduce_cells(found, n, half, per_shape, cos_max, spacing2, out)
    if refine_radius > 0.0 and count > 0:
        obstacle, normal = out.obstacle, out.normal
        at = np.empty((count, 3))
        for i in range(count):
            for a in range(3):
                at[i, a] = obstacle[i, a] + refine_offset * normal[i, a]
        metaball_normals(bricks, at, refine_radius, normal[:count])
    return count


#: Where each group of :func:`cell_contacts_flat`'s arguments ends.
_B = len(Bricks.__annotations__)
_S = _B + len(Shapes.__annotations__)
_R = _S + 11  # frames ... capacity


@numba.njit(cache=True, nogil=True)
def cell_contacts_flat(*args):  # type: ignore[no-untyped-def]
    """:func:`cell_contacts` with its named tuples' fields passed one by one.

    The arguments are the fields of the Bricks, then of the Shapes, then the
    other arguments up to ``capacity``, then the output: the shapes (K,) and
    one float array (4, K, 3) of the robot points, obstacle points, normals and
    (in ``[3, :, 0]``) distances (:meth:`Contacts.packed`). Numba's dispatcher
    types arrays in compiled code but named tuples in Python: the same call
    with named tuples costs about 2 us more, and three more arrays to allocate
    and slice about 1 us.
    """
    shape, floats = args[_R:]
    return cell_contacts(  # type: ignore[call-arg]  # a tuple of known length
        Bricks(*args[:_B]),
        Shapes(*args[_B:_S]),
        *args[_S:_R],
        Contacts(shape, floats[0], floats[1], floats[2], floats[3][:, 0]),
    )
