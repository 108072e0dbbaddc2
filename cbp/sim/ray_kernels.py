# SPDX-License-Identifier: Apache-2.0
"""The compiled ray cast of :class:`~cbp.sim.raycast.RayCaster`: depth per pixel.

For every pixel's ray, the nearest surface: triangles visited one by one
(each covers the pixels whose rays cross it; a pixel keeps the nearest
crossing), spheres, cylinders and capsules intersected analytically over the
pixels their bounding box covers. :func:`cast` fills a depth image [m];
:func:`depth_buffer` turns it into the [0, 1] buffer the tiny renderer gives.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from cbp.robot import FloatArray

__all__ = ["CAPSULE", "CYLINDER", "SPHERE", "cast", "depth_buffer"]

#: A point or direction (x, y, z), as the compiled ray cast passes them.
Point = tuple[float, float, float]

#: Analytic shapes: kind codes in the shape table.
SPHERE, CYLINDER, CAPSULE = 0, 1, 2


class _Canvas(NamedTuple):
    """The depth buffer a compiled pass draws in, and the camera's terms."""

    fx: float
    """The projection's horizontal focal term (``projection[0, 0]``)."""
    fy: float
    """Its vertical one (``projection[1, 1]``)."""
    near: float
    """The clipping plane [m]: nearer surfaces are cut away."""
    far: float
    """The far plane [m]: surfaces at or beyond it are not seen."""
    depth: FloatArray
    """Each pixel's nearest depth so far (H, W) [m] (inf: none)."""


@numba.njit(cache=True, nogil=True)
def cast(
    triangles: FloatArray,
    tri_part: np.ndarray,
    shapes: FloatArray,
    shape_part: np.ndarray,
    to_camera: FloatArray,
    fx: float,
    fy: float,
    near: float,
    far: float,
    depth: FloatArray,
) -> None:  # pragma: no cover - compiled
    """Keep in ``depth`` (H, W) [m] the nearer of it and the surfaces' depth."""
    canvas = _Canvas(fx, fy, near, far, depth)
    poly = np.empty((4, 3))
    v = np.empty((3, 3))
    for t in range(len(triangles)):
        M = to_camera[tri_part[t]]
        for i in range(3):
            for r in range(3):
                v[i, r] = (
                    M[r, 0] * triangles[t, i, 0]
                    + M[r, 1] * triangles[t, i, 1]
                    + M[r, 2] * triangles[t, i, 2]
                    + M[r, 3]
                )
        # Clip against the near plane (depth = -z >= near): 0, 3 or 4 corners.
        n = 0
        for i in range(3):
            a = v[i]
            b = v[(i + 1) % 3]
            da = -a[2] - near
            db = -b[2] - near
            if da >= 0.0:
                poly[n] = a
                n += 1
            if (da >= 0.0) != (db >= 0.0):
                s = da / (da - db)
                for r in range(3):
                    poly[n, r] = a[r] + s * (b[r] - a[r])
                n += 1
        if n < 3:
            continue
        for k in range(1, n - 1):
            _triangle(poly[0], poly[k], poly[k + 1], canvas)
    for s in range(len(shapes)):
        _analytic(shapes[s], to_camera[shape_part[s]], canvas)


@numba.njit(cache=True, nogil=True)
def depth_buffer(depth: FloatArray, near: float, far: float) -> FloatArray:
    """The depth buffer in [0, 1] of depths [m] (1 where nothing is seen)."""
    h, w = depth.shape
    out = np.empty((h, w))
    scale = far / (far - near)
    for r in range(h):
        for c in range(w):
            d = depth[r, c]
            out[r, c] = scale * (1.0 - near / d) if d < far else 1.0
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _pixel(
    x: float, y: float, z: float, fx: float, fy: float, w: int, h: int
) -> tuple[float, float]:  # pragma: no cover
    """Column and row (continuous) where the camera-frame point projects."""
    d = -z
    return (x / d * fx + 1.0) * 0.5 * w, h - 1.0 - (y / d * fy + 1.0) * 0.5 * h


@numba.njit(cache=True, nogil=True)
def _triangle(
    a: FloatArray,
    b: FloatArray,
    c: FloatArray,
    canvas: _Canvas,
) -> None:  # pragma: no cover - compiled
    """Keep, at each pixel whose ray crosses triangle abc, the nearer depth."""
    fx, fy, near, far, depth = canvas
    h, w = depth.shape
    # The plane n . p = k; a pixel's ray p = t (X, Y, -1) meets it at
    # t = k / n . (X, Y, -1).
    e1x, e1y, e1z = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    e2x, e2y, e2z = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    k = nx * a[0] + ny * a[1] + nz * a[2]
    if k == 0.0:  # seen edge-on
        return
    au, av = _pixel(a[0], a[1], a[2], fx, fy, w, h)
    bu, bv = _pixel(b[0], b[1], b[2], fx, fy, w, h)
    cu, cv = _pixel(c[0], c[1], c[2], fx, fy, w, h)
    area = (bu - au) * (cv - av) - (bv - av) * (cu - au)
    if area == 0.0:
        return
    v0 = max(int(np.ceil(min(av, bv, cv))), 0)
    v1 = min(int(np.floor(max(av, bv, cv))), h - 1)
    sign = 1.0 if area > 0.0 else -1.0
    # Edge functions s ((q - p) x (pixel - p)) >= 0 for the edges pq: linear in
    # the column, so each row's pixels inside form one span.
    edges = ((bu, bv, cu, cv), (cu, cv, au, av), (au, av, bu, bv))
    for row in range(v0, v1 + 1):
        lo, hi = 0.0, w - 1.0
        for pu, pv, qu, qv in edges:
            slope = -sign * (qv - pv)
            rest = sign * ((qu - pu) * (row - pv) + (qv - pv) * pu)
            if slope > 0.0:
                lo = max(lo, -rest / slope)
            elif slope < 0.0:
                hi = min(hi, -rest / slope)
            elif rest < 0.0:
                hi = -1.0
        Y = (2.0 * (h - 1 - row) / h - 1.0) / fy
        base = ny * Y - nz
        for col in range(int(np.ceil(lo)), int(np.floor(hi)) + 1):
            den = nx * (2.0 * col / w - 1.0) / fx + base
            if den == 0.0:
                continue
            t = k / den
            if near <= t < depth[row, col] and t < far:
                depth[row, col] = t


@numba.njit(cache=True, nogil=True)
def _analytic(
    shape: FloatArray,
    M: FloatArray,
    canvas: _Canvas,
) -> None:  # pragma: no cover - compiled
    """Ray cast a sphere, cylinder or capsule (axis z of ``M``) pixel by pixel."""
    fx, fy, near, far, depth = canvas
    h, w = depth.shape
    kind, r, hl = int(shape[0]), shape[1], shape[2]
    reach = r if kind == SPHERE else (hl + r if kind == CAPSULE else hl)
    # Pixels: the projection of the shape's bounding box, or all of them.
    u0, u1, v0, v1 = w, -1, h, -1
    whole = False
    for i in range(8):
        lx = r if i & 1 else -r
        ly = r if i & 2 else -r
        lz = reach if i & 4 else -reach
        x = M[0, 0] * lx + M[0, 1] * ly + M[0, 2] * lz + M[0, 3]
        y = M[1, 0] * lx + M[1, 1] * ly + M[1, 2] * lz + M[1, 3]
        z = M[2, 0] * lx + M[2, 1] * ly + M[2, 2] * lz + M[2, 3]
        if -z < near:
            whole = True
            break
        pu, pv = _pixel(x, y, z, fx, fy, w, h)
        u0 = min(u0, int(np.ceil(pu)))
        u1 = max(u1, int(np.floor(pu)))
        v0 = min(v0, int(np.ceil(pv)))
        v1 = max(v1, int(np.floor(pv)))
    if whole:
        u0, u1, v0, v1 = 0, w - 1, 0, h - 1
    u0, u1, v0, v1 = max(u0, 0), min(u1, w - 1), max(v0, 0), min(v1, h - 1)
    # The ray from the optical centre, in the shape's frame: o + t d.
    ox = -(M[0, 0] * M[0, 3] + M[1, 0] * M[1, 3] + M[2, 0] * M[2, 3])
    oy = -(M[0, 1] * M[0, 3] + M[1, 1] * M[1, 3] + M[2, 1] * M[2, 3])
    oz = -(M[0, 2] * M[0, 3] + M[1, 2] * M[1, 3] + M[2, 2] * M[2, 3])
    origin = (ox, oy, oz)
    for row in range(v0, v1 + 1):
        Y = (2.0 * (h - 1 - row) / h - 1.0) / fy
        for col in range(u0, u1 + 1):
            X = (2.0 * col / w - 1.0) / fx
            dx = M[0, 0] * X + M[1, 0] * Y - M[2, 0]
            dy = M[0, 1] * X + M[1, 1] * Y - M[2, 1]
            dz = M[0, 2] * X + M[1, 2] * Y - M[2, 2]
            t = _first_hit(kind, r, hl, origin, (dx, dy, dz), near)
            if t < depth[row, col] and t < far:
                depth[row, col] = t


@numba.njit(cache=True, nogil=True, inline="always")
def _sphere_hit(r: float, o: Point, d: Point, near: float) -> float:  # pragma: no cover
    """First t >= near where o + t d lies on the sphere of radius r at 0 (inf)."""
    ox, oy, oz = o
    dx, dy, dz = d
    a = dx * dx + dy * dy + dz * dz
    b = ox * dx + oy * dy + oz * dz
    c = ox * ox + oy * oy + oz * oz - r * r
    disc = b * b - a * c
    if disc < 0.0:
        return np.inf
    root = math.sqrt(disc)
    t = (-b - root) / a
    if t >= near:
        return t
    t = (-b + root) / a
    return t if t >= near else math.inf


@numba.njit(cache=True, nogil=True)
def _first_hit(
    kind: int,
    r: float,
    hl: float,
    o: Point,
    d: Point,
    near: float,
) -> float:  # pragma: no cover - compiled
    """Nearest t >= near where o + t d meets the shape's surface (inf if none)."""
    if kind == SPHERE:
        return _sphere_hit(r, o, d, near)
    ox, oy, oz = o
    dx, dy, dz = d
    best = np.inf
    # The side: (ox + t dx)^2 + (oy + t dy)^2 = r^2, |oz + t dz| <= hl.
    a = dx * dx + dy * dy
    if a > 0.0:
        b = ox * dx + oy * dy
        c = ox * ox + oy * oy - r * r
        disc = b * b - a * c
        if disc >= 0.0:
            root = np.sqrt(disc)
            for t in ((-b - root) / a, (-b + root) / a):
                if near <= t < best and abs(oz + t * dz) <= hl:
                    best = t
    if kind == CYLINDER:
        if dz != 0.0:
            for zc in (-hl, hl):
                t = (zc - oz) / dz
                if near <= t < best:
                    x = ox + t * dx
                    y = oy + t * dy
                    if x * x + y * y <= r * r:
                        best = t
        return best
    for zc in (-hl, hl):  # the capsule's two half spheres
        t = _sphere_hit(r, (ox, oy, oz - zc), d, near)
        if t < best:
            best = t
    return best
