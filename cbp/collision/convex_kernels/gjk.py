# SPDX-License-Identifier: Apache-2.0
"""GJK: the signed distance of two placed shapes, witness points and normal.

Gilbert, Johnson and Keerthi's algorithm finds the point of the cores'
Minkowski difference A - B nearest the origin, the closest point of the
current simplex by its Voronoi regions; where the cores overlap, EPA
(:mod:`cbp.collision.convex_kernels.epa`) measures how deep.
:func:`pair_distance` then takes both radii off the cores' distance.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cbp.collision.convex_kernels.epa import FAILED, epa
from cbp.collision.convex_kernels.packing import UNSUPPORTED
from cbp.collision.convex_kernels.support import PlacedConvex, support_pair
from cbp.robot import FloatArray

__all__ = ["GJK_TOLERANCE", "measure", "pair_distance"]

#: GJK stops when a support point improves the distance bound by less [m].
GJK_TOLERANCE = 1e-10
_GJK_ITERATIONS = 128


@numba.njit(cache=True, nogil=True)
def _triangle(
    W: FloatArray, a: int, b: int, c: int
) -> tuple[float, float, float, float]:
    """Weights of triangle (a, b, c)'s point nearest the origin, its distance².

    By the triangle's Voronoi regions (vertices, edges, inside).
    """
    abx, aby, abz = W[b, 0] - W[a, 0], W[b, 1] - W[a, 1], W[b, 2] - W[a, 2]
    acx, acy, acz = W[c, 0] - W[a, 0], W[c, 1] - W[a, 1], W[c, 2] - W[a, 2]
    d1 = -(abx * W[a, 0] + aby * W[a, 1] + abz * W[a, 2])
    d2 = -(acx * W[a, 0] + acy * W[a, 1] + acz * W[a, 2])
    u = v = w = 0.0
    if d1 <= 0.0 and d2 <= 0.0:
        u = 1.0
    else:
        d3 = -(abx * W[b, 0] + aby * W[b, 1] + abz * W[b, 2])
        d4 = -(acx * W[b, 0] + acy * W[b, 1] + acz * W[b, 2])
        d5 = -(abx * W[c, 0] + aby * W[c, 1] + abz * W[c, 2])
        d6 = -(acx * W[c, 0] + acy * W[c, 1] + acz * W[c, 2])
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            v = 1.0
        elif d6 >= 0.0 and d5 <= d6:
            w = 1.0
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            v = d1 / (d1 - d3)
            u = 1.0 - v
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            w = d2 / (d2 - d6)
            u = 1.0 - w
        elif va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
            w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            v = 1.0 - w
        else:
            total = va + vb + vc
            v, w = vb / total, vc / total
            u = 1.0 - v - w
    x = u * W[a, 0] + v * W[b, 0] + w * W[c, 0]
    y = u * W[a, 1] + v * W[b, 1] + w * W[c, 1]
    z = u * W[a, 2] + v * W[b, 2] + w * W[c, 2]
    return u, v, w, x * x + y * y + z * z


@numba.njit(cache=True, nogil=True)
def _closest(W: FloatArray, n: int, lam: FloatArray) -> bool:
    """The point of the simplex W[:n] nearest the origin, as weights ``lam``.

    Returns True when the origin is inside the tetrahedron (n = 4). Weights of
    the points that are not needed are 0.
    """
    for i in range(4):
        lam[i] = 0.0
    if n == 1:
        lam[0] = 1.0
    elif n == 2:
        abx, aby, abz = W[1, 0] - W[0, 0], W[1, 1] - W[0, 1], W[1, 2] - W[0, 2]
        length2 = abx * abx + aby * aby + abz * abz
        t = -(abx * W[0, 0] + aby * W[0, 1] + abz * W[0, 2])
        t = t / length2 if length2 > 0.0 else 0.0
        t = min(max(t, 0.0), 1.0)
        lam[0], lam[1] = 1.0 - t, t
    elif n == 3:
        lam[0], lam[1], lam[2], _ = _triangle(W, 0, 1, 2)
    else:
        # Each face whose plane has the origin on the side away from the
        # fourth point; the nearest of their nearest points. None: inside.
        best = np.inf
        inside = True
        faces = ((0, 1, 2, 3), (0, 1, 3, 2), (0, 2, 3, 1), (1, 2, 3, 0))
        ax, ay, az = W[1, 0] - W[0, 0], W[1, 1] - W[0, 1], W[1, 2] - W[0, 2]
        bx, by, bz = W[2, 0] - W[0, 0], W[2, 1] - W[0, 1], W[2, 2] - W[0, 2]
        cx, cy, cz = W[3, 0] - W[0, 0], W[3, 1] - W[0, 1], W[3, 2] - W[0, 2]
        volume = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx)
        volume += az * (bx * cy - by * cx)
        scale = max(ax * ax + ay * ay + az * az, bx * bx + by * by + bz * bz)
        scale = max(scale, cx * cx + cy * cy + cz * cz)
        flat = abs(volume) <= 1e-12 * scale**1.5
        for a, b, c, d in faces:
            ex, ey, ez = W[b, 0] - W[a, 0], W[b, 1] - W[a, 1], W[b, 2] - W[a, 2]
            fx, fy, fz = W[c, 0] - W[a, 0], W[c, 1] - W[a, 1], W[c, 2] - W[a, 2]
            nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
            origin = -(nx * W[a, 0] + ny * W[a, 1] + nz * W[a, 2])
            other = (
                nx * (W[d, 0] - W[a, 0])
                + ny * (W[d, 1] - W[a, 1])
                + nz * (W[d, 2] - W[a, 2])
            )
            if not flat and origin * other >= 0.0:
                continue  # the origin is on the fourth point's side
            inside = False
            u, v, w, dist2 = _triangle(W, a, b, c)
            if dist2 < best:
                best = dist2
                lam[a], lam[b], lam[c], lam[d] = u, v, w, 0.0
        if inside:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _compact(
    W: FloatArray, WA: FloatArray, WB: FloatArray, lam: FloatArray, n: int
) -> int:
    """Drop the simplex points of weight 0; return how many are left."""
    m = 0
    for i in range(n):
        if lam[i] > 0.0:
            if m != i:
                for a in range(3):
                    W[m, a], WA[m, a], WB[m, a] = W[i, a], WA[i, a], WB[i, a]
                lam[m] = lam[i]
            m += 1
    return m


@numba.njit(cache=True, nogil=True)
def pair_distance(
    shape_a: PlacedConvex,
    shape_b: PlacedConvex,
    guess: FloatArray,
    work: FloatArray,
    out: FloatArray,
) -> int:
    """Signed distance of shape A from shape B, witnesses and normal (B toward A).

    Args:
        shape_a: A where it stands.
        shape_b: B, likewise.
        guess: (5,): where to start, updated for the next call: the last
            normal (zeros: none yet) and the hulls' last support vertices.
            Between small motions, GJK then needs a few iterations.
        work: scratch, (16, 3) floats.
        out: (10,): distance, the point on A, the point on B, the unit normal
            from B toward A.

    Returns:
        0, or :data:`FAILED` when EPA could not start (``out`` is then unset).
    """
    W = work[0:4]
    WA = work[4:8]
    WB = work[8:12]
    lam = work[12:16, 0]
    # Start from the last call's normal and vertices, else along the line
    # between the frames' origins.
    hint_a, hint_b = int(guess[3]), int(guess[4])
    vx, vy, vz = guess[0], guess[1], guess[2]
    if vx * vx + vy * vy + vz * vz < 1e-24:
        vx = shape_a.frame[0, 3] - shape_b.frame[0, 3]
        vy = shape_a.frame[1, 3] - shape_b.frame[1, 3]
        vz = shape_a.frame[2, 3] - shape_b.frame[2, 3]
    if vx * vx + vy * vy + vz * vz < 1e-24:
        vx, vy, vz = 1.0, 0.0, 0.0
    n = 0
    vv = np.inf
    ax = ay = az = bx = by = bz = 0.0
    overlap = False
    for _ in range(_GJK_ITERATIONS):
        pax, pay, paz, pbx, pby, pbz, hint_a, hint_b = support_pair(
            shape_a, shape_b, hint_a, hint_b, -vx, -vy, -vz
        )
        wx, wy, wz = pax - pbx, pay - pby, paz - pbz
        if n > 0:
            gap = vv - (vx * wx + vy * wy + vz * wz)
            if gap <= GJK_TOLERANCE * math.sqrt(vv) or gap <= 1e-14 * vv:
                break  # no support point brings the bound down any more
            repeated = False
            for i in range(n):
                if W[i, 0] == wx and W[i, 1] == wy and W[i, 2] == wz:
                    repeated = True
            if repeated:
                break
        W[n, 0], W[n, 1], W[n, 2] = wx, wy, wz
        WA[n, 0], WA[n, 1], WA[n, 2] = pax, pay, paz
        WB[n, 0], WB[n, 1], WB[n, 2] = pbx, pby, pbz
        n += 1
        if _closest(W, n, lam):
            overlap = True
            break
        n = _compact(W, WA, WB, lam, n)
        nx = ny = nz = 0.0
        cax = cay = caz = cbx = cby = cbz = 0.0
        for i in range(n):
            nx += lam[i] * W[i, 0]
            ny += lam[i] * W[i, 1]
            nz += lam[i] * W[i, 2]
            cax += lam[i] * WA[i, 0]
            cay += lam[i] * WA[i, 1]
            caz += lam[i] * WA[i, 2]
            cbx += lam[i] * WB[i, 0]
            cby += lam[i] * WB[i, 1]
            cbz += lam[i] * WB[i, 2]
        new = nx * nx + ny * ny + nz * nz
        if new >= vv:
            break  # no progress (round-off): keep the last point
        vx, vy, vz, vv = nx, ny, nz, new
        ax, ay, az, bx, by, bz = cax, cay, caz, cbx, cby, cbz
        if vv <= 1e-24:
            overlap = True  # touching: EPA tells how deep
            break
    if not overlap:
        core = math.sqrt(vv)
        ux, uy, uz = vx / core, vy / core, vz / core
    else:
        status = epa(shape_a, shape_b, hint_a, hint_b, W, WA, WB, n, out)
        if status != 0:
            return status
        core = out[0]
        ax, ay, az = out[1], out[2], out[3]
        bx, by, bz = out[4], out[5], out[6]
        ux, uy, uz = out[7], out[8], out[9]
    guess[0], guess[1], guess[2] = ux, uy, uz
    guess[3], guess[4] = hint_a, hint_b
    ra, rb = shape_a.radius, shape_b.radius
    out[0] = core - ra - rb
    out[1], out[2], out[3] = ax - ra * ux, ay - ra * uy, az - ra * uz
    out[4], out[5], out[6] = bx + rb * ux, by + rb * uy, bz + rb * uz
    out[7], out[8], out[9] = ux, uy, uz
    return 0


@numba.njit(cache=True, nogil=True, inline="always")
def measure(
    a: PlacedConvex,
    b: PlacedConvex,
    guess: FloatArray,
    work: FloatArray,
    out: FloatArray,
) -> int:
    """:func:`pair_distance`, or :data:`FAILED` for a shape the kernels skip."""
    if a.kind == UNSUPPORTED or b.kind == UNSUPPORTED:
        return FAILED
    return pair_distance(a, b, guess, work, out)
