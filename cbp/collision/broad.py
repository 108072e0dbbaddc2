# SPDX-License-Identifier: Apache-2.0
"""The broad phase of the contact queries, compiled: which pairs reach coal.

Every robot shape carries a bounding sphere and a bounding box about the same
centre, in its own frame. Rotated into the world, the box gives a world-aligned
box; a (shape, object) or (shape, shape) pair goes on to coal's exact distance
only when both the spheres and the boxes are within the margin. On long links
and thin objects the boxes cut the calls to coal by about 40 % against spheres
alone (the boards scene: 7.9 calls per query down to 4.8).

The tests are a few dozen flops per pair, for tens of pairs; compiled, the whole
broad phase costs about what one numpy call does.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cbp.robot import FloatArray, IntArray

__all__ = ["near_objects", "near_pairs", "shape_bounds"]


@numba.njit(cache=True, nogil=True)
def shape_bounds(
    frames: FloatArray,
    centres_local: FloatArray,
    halves_local: FloatArray,
    centres: FloatArray,
    halves: FloatArray,
) -> None:
    """World bounding-sphere centres and box half extents of the shapes.

    Args:
        frames: the shapes' world placements as homogeneous matrices (n, 4, 4).
        centres_local: the centres in the shapes' frames (n, 3).
        halves_local: the boxes' half extents in the shapes' frames (n, 3).
        centres: out, the centres in the world (n, 3).
        halves: out, the half extents of world-aligned boxes around the rotated
            boxes (n, 3).
    """
    for s in range(len(frames)):
        for a in range(3):
            c = frames[s, a, 3]
            h = 0.0
            for b in range(3):
                c += frames[s, a, b] * centres_local[s, b]
                h += abs(frames[s, a, b]) * halves_local[s, b]
            centres[s, a] = c
            halves[s, a] = h


@numba.njit(cache=True, nogil=True)
def near_objects(
    centres: FloatArray,
    halves: FloatArray,
    radii: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    candidates: IntArray,
    margin: float,
) -> tuple[IntArray, IntArray]:
    """The (shape, object) pairs whose bounds are within ``margin``.

    Objects are world-aligned boxes (``lower``, ``upper``); only those listed in
    ``candidates`` are tested, and first against the box around all the shapes'
    spheres, so that objects far from the robot cost one test each.

    Returns:
        The pairs' shapes and objects, shape-major.
    """
    capacity = len(centres) * len(candidates)
    out_shape = np.empty(capacity, dtype=np.intp)
    out_object = np.empty(capacity, dtype=np.intp)
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for s in range(len(centres)):
        for a in range(3):
            lo[a] = min(lo[a], centres[s, a] - radii[s] - margin)
            hi[a] = max(hi[a], centres[s, a] + radii[s] + margin)
    near = np.empty(len(candidates), dtype=np.int64)
    count = 0
    for k in candidates:
        if (
            (lower[k, 0] <= hi[0])
            & (upper[k, 0] >= lo[0])
            & (lower[k, 1] <= hi[1])
            & (upper[k, 1] >= lo[1])
            & (lower[k, 2] <= hi[2])
            & (upper[k, 2] >= lo[2])
        ):
            near[count] = k
            count += 1
    n = 0
    m2 = margin * margin
    for s in range(len(centres)):
        for k in near[:count]:
            sphere = 0.0
            box = 0.0
            for a in range(3):
                gap = max(lower[k, a] - centres[s, a], 0.0) + max(
                    centres[s, a] - upper[k, a], 0.0
                )
                sphere += gap * gap
                gap = max(gap - halves[s, a], 0.0)
                box += gap * gap
            if box < m2 and math.sqrt(sphere) - radii[s] < margin:
                out_shape[n] = s
                out_object[n] = k
                n += 1
    return out_shape[:n], out_object[:n]


@numba.njit(cache=True, nogil=True)
def near_pairs(
    centres: FloatArray,
    halves: FloatArray,
    radii: FloatArray,
    first: IntArray,
    second: IntArray,
    margin: float,
    out: IntArray,
) -> int:
    """The indices of the shape pairs (``first``, ``second``) within ``margin``.

    Writes them in order to ``out`` and returns their number.
    """
    n = 0
    m2 = margin * margin
    for k in range(len(first)):
        a, b = first[k], second[k]
        sphere = 0.0
        box = 0.0
        for x in range(3):
            d = centres[a, x] - centres[b, x]
            sphere += d * d
            gap = max(abs(d) - halves[a, x] - halves[b, x], 0.0)
            box += gap * gap
        reach = radii[a] + radii[b] + margin
        if sphere < reach * reach and box < m2:
            out[n] = k
            n += 1
    return n


def compile_broad_phase() -> None:
    """Compile the kernels (or load them from numba's cache) on tiny inputs."""
    frames = np.tile(np.eye(4), (2, 1, 1))
    centres, halves = np.zeros((2, 3)), np.zeros((2, 3))
    shape_bounds(frames, np.zeros((2, 3)), np.ones((2, 3)), centres, halves)
    radii = np.ones(2)
    pairs = np.zeros(1, dtype=np.intp)
    out = np.empty(2, dtype=np.intp)
    near_objects(centres, halves, radii, centres, centres + 1.0, pairs, 0.1)
    near_pairs(centres, halves, radii, pairs, pairs + 1, 0.1, out)
