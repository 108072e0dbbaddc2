# SPDX-License-Identifier: Apache-2.0
"""Depth readings into the grid: occupied cells, the robot's own, hidden space.

Each reading of a frame is unprojected; one on the robot (inside a shape
grown by its reach) is dropped, one that came nearer than the space seen free
along its pixel hides what lies behind it, and the others make their cells
occupied (:func:`insert_readings`). The cells entered by something that came
between are kept for a while (:func:`merge_entered`,
:func:`occupied_centres`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cbp.collision.geometry import inside_any
from cbp.perception.kernels.arrays import (
    FREE,
    KEPT_NONE,
    KEPT_ROBOT,
    OCCUPIED,
    UNKNOWN,
    FrameArrays,
    GridArrays,
    KeptPixels,
    PixelHistory,
    RobotShapes,
)
from cbp.perception.kernels.pixels import holds_reading
from cbp.robot import FloatArray, IntArray

__all__ = ["insert_readings", "merge_entered", "occupied_centres"]


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

    Only the pixels ``todo`` marks
    (:func:`~cbp.perception.kernels.frame_changes`) are integrated so; each
    other pixel holding a reading keeps the cell its last integrated reading
    made occupied (``kept.cell``) occupied with no misses, as that reading
    would. ``kept`` takes what each integrated pixel did.

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
            if not holds_reading(z, nearest, far_buffer):
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
