# SPDX-License-Identifier: Apache-2.0
"""A depth image's pixels: ranges eroded over 3 x 3, what changed, its windows.

Per pixel of a depth buffer: whether it holds a reading, its range along the
axis eroded over its neighbours (a cell is seen through only in front of all
the pixels it spans), which pixels changed since the last integrated frame,
and the changed tiles as windows of the image.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cbp.perception.kernels.arrays import KEPT_ROBOT, FrameArrays, KeptPixels
from cbp.robot import FloatArray, IntArray

__all__ = [
    "eroded_at",
    "eroded_ranges",
    "eroded_ranges_in",
    "frame_changes",
    "holds_reading",
    "tile_windows",
]


@numba.njit(cache=True, nogil=True, inline="always")
def holds_reading(z: float, nearest: float, far_buffer: float) -> bool:
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
            elif not holds_reading(z, nearest, far_buffer):
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
    if not holds_reading(z, nearest, far_buffer):
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
                out[r, c] = eroded_at(
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


@numba.njit(cache=True, nogil=True, inline="always")
def eroded_at(
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
            if not holds_reading(z, nearest, far_buffer):
                v = -np.inf
            elif z >= far_plane:
                v = far
            else:
                v = far * near / (far - (far - near) * z)
            least = _least(least, v)
    return -np.inf if np.isnan(least) else least
