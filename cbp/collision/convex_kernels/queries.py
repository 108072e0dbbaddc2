# SPDX-License-Identifier: Apache-2.0
"""The contact queries of the compiled narrow phase, and their warm-up.

One compiled pass measures every pair the broad phase
(:mod:`cbp.collision.broad`) keeps, each from its last normal and support
vertices, and writes the contacts to flat arrays: the robot's shapes against
declared objects (:func:`obstacle_contacts`), against each other
(:func:`self_contacts`), both in one call (:func:`declared_contacts`), and the
planners' yes-or-no self check (:func:`self_overlap`).
:func:`compile_convex_kernels` compiles them (or loads them from numba's
cache) on tiny inputs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import coal
import numba
import numpy as np
import numpy.typing as npt

from cbp.collision.broad import near_objects, near_pairs, shape_bounds
from cbp.collision.convex_kernels.gjk import measure
from cbp.collision.convex_kernels.packing import (
    LocalBounds,
    SelfPairs,
    Table,
    fields,
    pack_shapes,
    packed_robot,
)
from cbp.collision.convex_kernels.support import placed
from cbp.robot import FloatArray, IntArray

if TYPE_CHECKING:
    from cbp.collision.geometry import PlacedShapes

__all__ = [
    "Obstacles",
    "Placed",
    "compile_convex_kernels",
    "contact_buffers",
    "declared_contacts",
    "obstacle_contacts",
    "placed_robot",
    "self_contacts",
    "self_overlap",
]

#: A placed robot as the kernels take it (:func:`placed_robot`): its shapes'
#: bounds in the world (centres (n, 3), box half extents (n, 3), sphere radii
#: (n,), :mod:`cbp.collision.broad`'s), their placements (n, 4, 4) and their
#: packed :data:`Table`.
Placed = tuple[FloatArray, FloatArray, FloatArray, FloatArray, Table]
#: Declared objects as the kernels take them (a
#: :class:`~cbp.collision.objects.PrimitiveEnvironment` builds them): their
#: swept boxes ``lower``, ``upper`` (m, 3), the ``candidates`` to test (indices),
#: their placements (m, 4, 4) and packed :data:`Table`, ``skip`` (n, m) (the
#: wanted contacts, not measured), each pair's GJK start ``guess`` (n, m, 5)
#: (:func:`~cbp.collision.convex_kernels.pair_distance`'s), ``ahead`` (m, 3)
#: (each object's displacement over the look-ahead), whether any object moves,
#: and the margin [m].
Obstacles = tuple[
    FloatArray,
    FloatArray,
    IntArray,
    FloatArray,
    Table,
    npt.NDArray[np.bool_],
    FloatArray,
    FloatArray,
    bool,
    float,
]


@numba.njit(cache=True, nogil=True, inline="always")
def _write(floats: FloatArray, row: int, out: FloatArray, distance: float) -> None:
    """A contact into ``floats`` (4, K, 3): points, normal, then the distance."""
    for k in range(3):
        floats[0, row, k] = out[1 + k]
        floats[1, row, k] = out[4 + k]
        floats[2, row, k] = out[7 + k]
    floats[3, row, 0] = distance


@numba.njit(cache=True, nogil=True, inline="always")
def obstacle_contacts(
    robot: Placed,
    objects: Obstacles,
    index: IntArray,
    floats: FloatArray,
    left: IntArray,
) -> tuple[int, int]:
    """The robot shapes' contacts with declared objects, broad and narrow phase.

    The pairs :func:`~cbp.collision.broad.near_objects` keeps, except those
    the objects skip (wanted contacts), are measured (each from its
    ``guess``, :func:`~cbp.collision.convex_kernels.pair_distance`'s); those
    nearer than the margin are written: ``index`` (2, K) the shape and the
    object, ``floats`` (4, K, 3) the point on the shape, the point on the
    object, the unit normal from the object toward the shape and
    (``[3, :, 0]``) the distance. A moving
    object's distance is less its approach along the normal (its displacement
    over the look-ahead, ``ahead``).

    Pairs with a shape the kernels do not measure, or that EPA could not start
    on, are written to ``left`` (2, L), (shape, object), for coal.

    Returns:
        (contacts written, pairs left for coal).
    """
    centres, halves, radii, frames, table = robot
    lower, upper, candidates, object_frames, object_table = objects[:5]
    skip, guess, ahead, moving, margin = objects[5:]
    near_shape, near_object = near_objects(
        centres, halves, radii, lower, upper, candidates, margin
    )
    work = np.empty((16, 3))
    out = np.empty(10)
    count = 0
    missed = 0
    for p in range(len(near_shape)):
        s, k = near_shape[p], near_object[p]
        if skip[s, k]:
            continue
        status = measure(
            placed(table, frames, s),
            placed(object_table, object_frames, k),
            guess[s, k],
            work,
            out,
        )
        if status != 0:
            left[0, missed], left[1, missed] = s, k
            missed += 1
            continue
        d = out[0]
        if moving:
            d -= max(
                out[7] * ahead[k, 0] + out[8] * ahead[k, 1] + out[9] * ahead[k, 2],
                0.0,
            )
        if d < margin:
            index[0, count], index[1, count] = s, k
            _write(floats, count, out, d)
            count += 1
    return count, missed


@numba.njit(cache=True, nogil=True, inline="always")
def self_contacts(
    robot: Placed,
    pairs: SelfPairs,
    index: IntArray,
    floats: FloatArray,
    left: IntArray,
) -> tuple[int, int]:
    """The contacts between the robot's own shape pairs (``first``, ``second``).

    The pairs :func:`~cbp.collision.broad.near_pairs` keeps within the
    pairs' margin are measured (each from its ``self_guess``), shape
    ``second`` as B (the normal points from it toward ``first``); those nearer
    than the margin are written as :func:`obstacle_contacts` writes them,
    their distance less the pairs' padding. Pairs the kernels cannot measure
    go to ``left`` (2, L): -1, then the index into the pairs.

    Returns:
        (contacts written, pairs left for coal).
    """
    centres, halves, radii, frames, table = robot
    first, second, self_guess, margin, padding = pairs
    near = np.empty(len(first), dtype=np.intp)
    found = near_pairs(centres, halves, radii, first, second, margin, near)
    work = np.empty((16, 3))
    out = np.empty(10)
    count = 0
    missed = 0
    for p in range(found):
        i, j = first[near[p]], second[near[p]]
        status = measure(
            placed(table, frames, i),
            placed(table, frames, j),
            self_guess[near[p]],
            work,
            out,
        )
        if status != 0:
            left[0, missed], left[1, missed] = -1, near[p]
            missed += 1
        elif out[0] < margin:
            index[0, count], index[1, count] = i, j
            _write(floats, count, out, out[0] - padding)
            count += 1
    return count, missed


@numba.njit(cache=True, nogil=True)
def declared_contacts(
    frames: FloatArray,
    bounds: LocalBounds,
    objects: Obstacles,
    padding: float,
    pairs: SelfPairs,
    index: IntArray,
    floats: FloatArray,
    left: IntArray,
) -> tuple[int, int, int, int, int]:
    """A whole contact query against declared objects, in one call.

    The shapes' bounds from their world placements ``frames`` (n, 4, 4) and
    ``bounds`` in their own frames (:func:`~cbp.collision.broad.shape_bounds`),
    then :func:`obstacle_contacts` with distances less ``padding``, then
    :func:`self_contacts` of the ``pairs`` (none when empty).

    The contacts are written in order, obstacles first: ``index`` (2, K) holds
    the shape and the other shape (-1 for objects), ``floats`` (4, K, 3) the
    points, normals and distances as :func:`obstacle_contacts` writes them.
    ``left`` (2, L) gets the pairs left for coal: (shape, object) first, then
    (-1, self pair index).

    Returns:
        (obstacle contacts, self contacts, obstacle pairs left, self pairs left,
        the most obstacle contacts of any one shape).
    """
    centres_local, halves_local, radii, table = bounds
    n = len(frames)
    centres = np.empty((n, 3))
    halves = np.empty((n, 3))
    shape_bounds(frames, centres_local, halves_local, centres, halves)
    robot = (centres, halves, radii, frames, table)
    obstacles, obstacles_missed = obstacle_contacts(robot, objects, index, floats, left)
    per_shape = np.zeros(n, dtype=np.intp)
    most = 0
    for c in range(obstacles):
        index[1, c] = -1
        floats[3, c, 0] -= padding
        s = index[0, c]
        per_shape[s] += 1
        most = max(most, per_shape[s])
    own = own_missed = 0
    if len(pairs[0]):
        own, own_missed = self_contacts(
            robot,
            pairs,
            index[:, obstacles:],
            floats[:, obstacles:],
            left[:, obstacles_missed:],
        )
    return obstacles, own, obstacles_missed, own_missed, most


@numba.njit(cache=True, nogil=True)
def self_overlap(frames: FloatArray, bounds: LocalBounds, pairs: SelfPairs) -> int:
    """Whether two of the robot's shapes come nearer than the pairs' margin.

    The planners' yes-or-no self check: the shapes placed by ``frames``
    (n, 4, 4), the ``pairs`` the broad phase keeps measured in turn until the
    first nearer than their margin (``pairs``' fourth field; twice the padding
    checks the padded shapes for overlap).

    Returns:
        1 for a pair that near, 0 for none, -1 when a pair could not be
        measured (a shape the kernels skip) and none was found nearer.
    """
    centres_local, halves_local, radii, table = bounds
    first, second, self_guess, margin, _ = pairs
    n = len(frames)
    centres = np.empty((n, 3))
    halves = np.empty((n, 3))
    shape_bounds(frames, centres_local, halves_local, centres, halves)
    near = np.empty(len(first), dtype=np.intp)
    found = near_pairs(centres, halves, radii, first, second, margin, near)
    work = np.empty((16, 3))
    out = np.empty(10)
    answer = 0
    for p in range(found):
        k = near[p]
        status = measure(
            placed(table, frames, first[k]),
            placed(table, frames, second[k]),
            self_guess[k],
            work,
            out,
        )
        if status != 0:
            answer = -1
        elif out[0] < margin:
            return 1
    return answer


def placed_robot(robot: PlacedShapes) -> Placed:
    """A placed robot as the kernels take it (:data:`Placed`)."""
    return (
        robot.centres,
        robot.halves,
        robot.radii,
        robot.placements.homogeneous,
        fields(packed_robot(robot.shapes)),
    )


def compile_convex_kernels() -> None:
    """Compile the kernels (or load them from numba's cache) on tiny inputs."""
    shapes = fields(
        pack_shapes(
            [
                coal.Box(0.1, 0.1, 0.1),
                coal.Sphere(0.05),
                coal.Capsule(0.05, 0.1),
                coal.Cylinder(0.05, 0.1),
            ]
        )
    )
    frames = np.tile(np.eye(4), (4, 1, 1))
    frames[:, 0, 3] = 0.0, 0.2, 0.4, 0.6
    centres = np.ascontiguousarray(frames[:, :3, 3])
    halves = np.full((4, 3), 0.1)
    radii = np.full(4, 0.2)
    robot = (centres, halves, radii, frames, shapes)
    first = np.array([0, 1], dtype=np.intp)
    pairs = (first, first + 2, np.zeros((2, 5)), 0.1, 0.01)
    for moving in (False, True):
        # The same shapes as objects, every one a candidate.
        objects = (
            centres - 0.1,
            centres + 0.1,
            np.arange(4, dtype=np.intp),
            frames,
            shapes,
            np.zeros((4, 4), dtype=np.bool_),
            np.zeros((4, 4, 5)),
            np.zeros((4, 3)),
            moving,
            0.1,
        )
        obstacle_contacts(robot, objects, *contact_buffers(32))
        declared_contacts(
            frames,
            (centres, halves, radii, shapes),
            objects,
            0.01,
            pairs,
            *contact_buffers(32),
        )
    self_contacts(robot, pairs, *contact_buffers(32))


def contact_buffers(n: int) -> tuple[IntArray, FloatArray, IntArray]:
    """Room for ``n`` contacts as the contact kernels write them.

    ``index`` (2, n) and ``floats`` (4, n, 3), as
    :meth:`~cbp.collision.contacts.ContactSet.packed` reads them, and ``left``
    (2, n), the pairs the kernels leave to coal.
    """
    return (
        np.empty((2, n), dtype=np.intp),
        np.empty((4, n, 3)),
        np.empty((2, n), dtype=np.intp),
    )
