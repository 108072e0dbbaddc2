# SPDX-License-Identifier: Apache-2.0
"""EPA: the penetration of two overlapping cores, from GJK's last simplex.

The expanding polytope: a polytope inside A - B, grown by the support point
beyond its face nearest the origin until that face is on the boundary (within
:data:`EPA_TOLERANCE`). For polytopes it is the exact penetration depth; the
witness points are the origin's projection on that face, in barycentric
weights of the support points.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cbp.collision.convex_kernels.support import PlacedConvex, support_pair
from cbp.robot import FloatArray, IntArray

__all__ = ["EPA_TOLERANCE", "FAILED", "epa"]

#: Status of a pair that the kernels could not measure (a degenerate EPA start).
FAILED = 1
#: EPA stops when the face nearest the origin is this close to the boundary [m].
EPA_TOLERANCE = 1e-10
_EPA_VERTICES = 128
_EPA_FACES = 4 * _EPA_VERTICES
_EPA_EDGES = 3 * _EPA_FACES


@numba.njit(cache=True, nogil=True)
def _triangle_plane(
    P: FloatArray, a: int, b: int, c: int
) -> tuple[bool, float, float, float, float]:
    """Triangle (a, b, c)'s unit normal and offset; False first if degenerate."""
    ex, ey, ez = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2]
    fx, fy, fz = P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2]
    nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    if length <= 1e-30:
        return False, 0.0, 0.0, 0.0, 0.0
    nx, ny, nz = nx / length, ny / length, nz / length
    return True, nx, ny, nz, nx * P[a, 0] + ny * P[a, 1] + nz * P[a, 2]


@numba.njit(cache=True, nogil=True)
def _face_plane(P: FloatArray, faces: IntArray, f: int, plane: FloatArray) -> bool:
    """Face f's unit normal and offset into ``plane[f]``; False if degenerate."""
    ok, nx, ny, nz, d = _triangle_plane(P, faces[f, 0], faces[f, 1], faces[f, 2])
    if ok:
        plane[f, 0], plane[f, 1], plane[f, 2], plane[f, 3] = nx, ny, nz, d
    return ok


@numba.njit(cache=True, nogil=True)
def epa(
    shape_a: PlacedConvex,
    shape_b: PlacedConvex,
    hint_a: int,
    hint_b: int,
    W: FloatArray,
    WA: FloatArray,
    WB: FloatArray,
    n: int,
    out: FloatArray,
) -> int:
    """The cores' penetration: EPA from GJK's last simplex (it holds the origin).

    Writes (the cores' signed distance, point on A, point on B, normal from B
    toward A) to ``out``; returns 0, or :data:`FAILED`.
    """
    V = _EPA_VERTICES
    P = np.empty((V, 3))
    PA = np.empty((V, 3))
    PB = np.empty((V, 3))
    faces = np.empty((_EPA_FACES, 3), dtype=np.int64)
    plane = np.empty((_EPA_FACES, 4))
    # The slots of faces gone, for new ones (a polytope of n vertices has 2n - 4
    # faces); a step's faces seen, and its horizon's edges with their planes.
    free = np.empty(_EPA_FACES, dtype=np.int64)
    n_free = 0
    seeing = np.empty(_EPA_FACES, dtype=np.int64)
    horizon = np.empty((_EPA_EDGES, 2), dtype=np.int64)
    trial = np.empty((_EPA_EDGES, 4))
    alive = np.zeros(_EPA_FACES, dtype=np.bool_)
    edges = np.empty((_EPA_EDGES, 2), dtype=np.int64)
    for i in range(n):
        for a in range(3):
            P[i, a], PA[i, a], PB[i, a] = W[i, a], WA[i, a], WB[i, a]
    # A simplex of fewer than four points (the shapes touch, or the origin is
    # on a face of the simplex): grow it to a tetrahedron by the support points
    # farthest from its span.
    directions = np.empty((6, 3))
    while n < 4:
        if n == 1:
            directions[:] = 0.0
            for a in range(3):
                directions[2 * a, a] = 1.0
                directions[2 * a + 1, a] = -1.0
            count = 6
        elif n == 2:
            ux, uy, uz = P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2]
            # A direction across the segment, and one across both.
            if abs(ux) <= abs(uy) and abs(ux) <= abs(uz):
                qx, qy, qz = 0.0, -uz, uy
            elif abs(uy) <= abs(uz):
                qx, qy, qz = -uz, 0.0, ux
            else:
                qx, qy, qz = -uy, ux, 0.0
            rx, ry, rz = uy * qz - uz * qy, uz * qx - ux * qz, ux * qy - uy * qx
            directions[0] = qx, qy, qz
            directions[1] = -qx, -qy, -qz
            directions[2] = rx, ry, rz
            directions[3] = -rx, -ry, -rz
            count = 4
        else:
            ex, ey, ez = P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2]
            fx, fy, fz = P[2, 0] - P[0, 0], P[2, 1] - P[0, 1], P[2, 2] - P[0, 2]
            nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
            directions[0] = nx, ny, nz
            directions[1] = -nx, -ny, -nz
            count = 2
        best = 0.0
        bax = bay = baz = bbx = bby = bbz = 0.0
        for k in range(count):
            dx, dy, dz = directions[k, 0], directions[k, 1], directions[k, 2]
            pax, pay, paz, pbx, pby, pbz, hint_a, hint_b = support_pair(
                shape_a, shape_b, hint_a, hint_b, dx, dy, dz
            )
            P[n, 0], P[n, 1], P[n, 2] = pax - pbx, pay - pby, paz - pbz
            reach = _off_span(P, n)
            if reach > best:
                best = reach
                bax, bay, baz, bbx, bby, bbz = pax, pay, paz, pbx, pby, pbz
        if best <= 1e-9:
            return FAILED
        PA[n, 0], PA[n, 1], PA[n, 2] = bax, bay, baz
        PB[n, 0], PB[n, 1], PB[n, 2] = bbx, bby, bbz
        P[n, 0], P[n, 1], P[n, 2] = bax - bbx, bay - bby, baz - bbz
        n += 1
    # The tetrahedron's faces, turned outward.
    tetra = ((0, 1, 2), (0, 3, 1), (0, 2, 3), (1, 3, 2))
    cx = 0.25 * (P[0, 0] + P[1, 0] + P[2, 0] + P[3, 0])
    cy = 0.25 * (P[0, 1] + P[1, 1] + P[2, 1] + P[3, 1])
    cz = 0.25 * (P[0, 2] + P[1, 2] + P[2, 2] + P[3, 2])
    for f in range(4):
        a, b, c = tetra[f]
        faces[f, 0], faces[f, 1], faces[f, 2] = a, b, c
        if not _face_plane(P, faces, f, plane):
            return FAILED
        if plane[f, 0] * cx + plane[f, 1] * cy + plane[f, 2] * cz > plane[f, 3]:
            faces[f, 1], faces[f, 2] = c, b
            _face_plane(P, faces, f, plane)
        alive[f] = True
    face_count = 4
    nearest = 0
    while True:  # until the nearest face is on the boundary, or no room is left
        nearest = -1
        least = np.inf
        for f in range(face_count):
            if alive[f] and plane[f, 3] < least:
                least, nearest = plane[f, 3], f
        if nearest < 0:
            return FAILED
        dx, dy, dz = plane[nearest, 0], plane[nearest, 1], plane[nearest, 2]
        pax, pay, paz, pbx, pby, pbz, hint_a, hint_b = support_pair(
            shape_a, shape_b, hint_a, hint_b, dx, dy, dz
        )
        wx, wy, wz = pax - pbx, pay - pby, paz - pbz
        if dx * wx + dy * wy + dz * wz - least <= EPA_TOLERANCE:
            break  # the nearest face is on the boundary
        if n == _EPA_VERTICES:
            break  # out of room: the nearest face so far
        P[n, 0], P[n, 1], P[n, 2] = wx, wy, wz
        PA[n, 0], PA[n, 1], PA[n, 2] = pax, pay, paz
        PB[n, 0], PB[n, 1], PB[n, 2] = pbx, pby, pbz
        # The faces the new point sees go; their edges seen once are the horizon.
        gone = 0
        count = 0
        for f in range(face_count):
            if not alive[f]:
                continue
            seen = plane[f, 0] * wx + plane[f, 1] * wy + plane[f, 2] * wz
            if seen - plane[f, 3] > 1e-14 * max(1.0, abs(plane[f, 3])):
                seeing[gone] = f
                gone += 1
                for e in range(3):
                    if count < _EPA_EDGES:
                        edges[count, 0] = faces[f, e]
                        edges[count, 1] = faces[f, (e + 1) % 3]
                        count += 1
        # A step that would not keep the polytope convex around the origin (a
        # horizon of other than one loop, a new face flat or nearer than the
        # nearest) is round-off, as support points crowd on a curved side: it
        # broke the polytope once: a sphere in a cylinder came 1.2 cm short
        # of its depth. Stop at the nearest face instead.
        added = 0
        intact = True
        for e in range(count):
            a, b = edges[e, 0], edges[e, 1]
            shared = False
            for g in range(count):
                if edges[g, 0] == b and edges[g, 1] == a:
                    shared = True
                    break
            if shared:
                continue
            ok, nx, ny, nz, d = _triangle_plane(P, a, b, n)
            if not ok or d < least - EPA_TOLERANCE:
                intact = False
                break
            horizon[added, 0], horizon[added, 1] = a, b
            trial[added, 0], trial[added, 1], trial[added, 2] = nx, ny, nz
            trial[added, 3] = d
            added += 1
        room = n_free + gone + _EPA_FACES - face_count
        if not intact or added != gone + 2 or added > room:
            break
        for k in range(gone):
            alive[seeing[k]] = False
            free[n_free] = seeing[k]
            n_free += 1
        for k in range(added):
            if n_free > 0:
                n_free -= 1
                f = free[n_free]
            else:
                f = face_count
                face_count += 1
            faces[f, 0], faces[f, 1], faces[f, 2] = horizon[k, 0], horizon[k, 1], n
            for j in range(4):
                plane[f, j] = trial[k, j]
            alive[f] = True
        n += 1
    # The origin's projection on the nearest face, in barycentric weights.
    # Faces in one plane (a face of A - B cut in triangles) are equally near:
    # the one the projection falls in gives the witness points. So are faces
    # whose planes pass within the tolerance of it: near a curved side they
    # turn by 1e-4 rad from one to the next, and the projection on the
    # nearest (by 1e-14 m) fell outside it, in its neighbour (witnesses 14 um
    # apart across the normal, clipped to the nearest face).
    depth = plane[nearest, 3]
    px, py, pz = (
        depth * plane[nearest, 0],
        depth * plane[nearest, 1],
        depth * plane[nearest, 2],
    )
    f = nearest
    u, v, w = _barycentric(P, faces, plane, f, px, py, pz)
    worst = min(u, v, w)
    if worst < 0.0:
        for g in range(face_count):
            if not alive[g] or g == nearest:
                continue
            off = plane[g, 0] * px + plane[g, 1] * py + plane[g, 2] * pz - plane[g, 3]
            if abs(off) > EPA_TOLERANCE:
                continue
            gu, gv, gw = _barycentric(P, faces, plane, g, px, py, pz)
            if min(gu, gv, gw) > worst:
                f, u, v, w, worst = g, gu, gv, gw, min(gu, gv, gw)
    # What round-off leaves outside the face is clipped back to it.
    u, v, w = max(u, 0.0), max(v, 0.0), max(w, 0.0)
    total = u + v + w
    u, v, w = u / total, v / total, w / total
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    for k in range(3):
        out[1 + k] = u * PA[a, k] + v * PA[b, k] + w * PA[c, k]
        out[4 + k] = u * PB[a, k] + v * PB[b, k] + w * PB[c, k]
        # The normal from B toward A is the way out: against the face's.
        out[7 + k] = -plane[nearest, k]
    out[0] = -depth
    return 0


@numba.njit(cache=True, nogil=True)
def _off_span(P: FloatArray, n: int) -> float:
    """How far P[n] lies from the affine span of P[:n] (n = 1, 2 or 3)."""
    dx, dy, dz = P[n, 0] - P[0, 0], P[n, 1] - P[0, 1], P[n, 2] - P[0, 2]
    if n == 1:
        return math.sqrt(dx * dx + dy * dy + dz * dz)
    ux, uy, uz = P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2]
    if n == 2:
        cx, cy, cz = dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux
        length = math.sqrt(ux * ux + uy * uy + uz * uz)
        return math.sqrt(cx * cx + cy * cy + cz * cz) / max(length, 1e-300)
    vx, vy, vz = P[2, 0] - P[0, 0], P[2, 1] - P[0, 1], P[2, 2] - P[0, 2]
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    reach: float = abs(nx * dx + ny * dy + nz * dz) / max(length, 1e-300)
    return reach


@numba.njit(cache=True, nogil=True)
def _barycentric(
    P: FloatArray,
    faces: IntArray,
    plane: FloatArray,
    f: int,
    px: float,
    py: float,
    pz: float,
) -> tuple[float, float, float]:
    """Barycentric weights of p in face f's plane (negative outside the face).

    From the signed areas p makes with the face's edges, along its unit normal:
    on a long, thin face (two support points a few um apart on a curved side,
    the third far off) these keep the weights to rounding, where weights from
    the normal equations of its edges lost 1e-4 of the far vertex's (a witness
    10 um off along a box's edge).
    """
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    nx, ny, nz = plane[f, 0], plane[f, 1], plane[f, 2]
    ax, ay, az = P[a, 0] - px, P[a, 1] - py, P[a, 2] - pz
    bx, by, bz = P[b, 0] - px, P[b, 1] - py, P[b, 2] - pz
    cx, cy, cz = P[c, 0] - px, P[c, 1] - py, P[c, 2] - pz
    u = nx * (by * cz - bz * cy) + ny * (bz * cx - bx * cz) + nz * (bx * cy - by * cx)
    v = nx * (cy * az - cz * ay) + ny * (cz * ax - cx * az) + nz * (cx * ay - cy * ax)
    w = nx * (ay * bz - az * by) + ny * (az * bx - ax * bz) + nz * (ax * by - ay * bx)
    total = u + v + w  # twice the face's area
    if total <= 0.0:
        return 1.0, 0.0, 0.0
    return u / total, v / total, w / total
