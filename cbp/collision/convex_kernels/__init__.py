# SPDX-License-Identifier: Apache-2.0
"""Signed distances between convex shapes, compiled: GJK, then EPA where they overlap.

The contact queries against declared objects and between the robot's own shapes
measure each pair the broad phase keeps (:mod:`cbp.collision.broad`). Called
from Python, coal takes 3-5 us per pair plus the call's own cost; here one
compiled pass measures every pair and writes the contacts to flat arrays.

Each shape is a *core* grown by a radius: a convex hull (its vertices), a box
or a cylinder with radius 0, a sphere (a point) or a capsule (a segment) with
their radius (and any of them with coal's swept-sphere radius added). The
distance of two shapes is the distance of their cores less both radii, exact
for spheres and capsules, with the witness points moved along the normal.

- **GJK** (Gilbert, Johnson and Keerthi) finds the point of the cores'
  Minkowski difference A - B nearest the origin, the closest point of the
  current simplex by its Voronoi regions. It stops when a support point no
  longer brings the bound down by more than ``GJK_TOLERANCE`` [m]: for
  polytopes (hulls, boxes) that is the exact answer; for a cylinder's rim the
  distance is within that tolerance.
- **EPA** (expanding polytope) measures the penetration when the cores overlap:
  a polytope inside A - B, grown by the support point beyond its face nearest
  the origin until that face is on the boundary (within ``EPA_TOLERANCE``).
  For polytopes it is the exact penetration depth.

Results follow coal's convention (:func:`cbp.collision.environment.signed_distance`,
the obstacle or other shape B first): the normal points from B toward A, the
distance is negative when they overlap, and ``point_a - point_b = distance *
normal``. Where the shapes touch along a face, the witness points are one pair
of the many; the distance and normal are unique for separated shapes.

A hull's support point is found by climbing its edges from the last one (a
few dot products instead of one per vertex), and each pair's GJK starts from
its last normal and support vertices (``guess``): between two control steps
the shapes move little, and a pair takes a few iterations. A guess is only a
starting point: the distance and normal do not depend on it (to GJK's
tolerance), so two threads that query the same environment at once (each
writing its guesses) change how many iterations a pair takes, not the
contacts.

Shapes are packed in flat arrays (:class:`ConvexShapes`), which the kernels
take grouped in plain tuples (:data:`Table`, :data:`Placed`, :data:`Obstacles`,
:data:`SelfPairs`): numba types a plain tuple of arrays in its compiled
dispatcher (about 0.1 us for a whole query's arguments, as for the arrays one
by one), a named tuple in Python (about 0.5 us for each of them). Inside the
kernels, one shape where it stands is a :class:`PlacedConvex`, and one
function gives the support point of A - B for GJK and EPA alike.

By what they compute: :mod:`~cbp.collision.convex_kernels.packing` (the flat
arrays), :mod:`~cbp.collision.convex_kernels.support` (a placed shape's
support point), :mod:`~cbp.collision.convex_kernels.gjk` and
:mod:`~cbp.collision.convex_kernels.epa` (one pair's distance), and
:mod:`~cbp.collision.convex_kernels.queries` (the contact queries over many
pairs, with their warm-up, :func:`compile_convex_kernels`).
"""

from cbp.collision.convex_kernels.epa import EPA_TOLERANCE, FAILED
from cbp.collision.convex_kernels.gjk import GJK_TOLERANCE, pair_distance
from cbp.collision.convex_kernels.packing import (
    BOX,
    CAPSULE,
    CONVEX,
    CYLINDER,
    SPHERE,
    UNSUPPORTED,
    ConvexShapes,
    LocalBounds,
    RobotTable,
    SelfPairs,
    Table,
    fields,
    pack_shapes,
    packed_robot,
)
from cbp.collision.convex_kernels.queries import (
    Obstacles,
    Placed,
    compile_convex_kernels,
    contact_buffers,
    declared_contacts,
    obstacle_contacts,
    placed_robot,
    self_contacts,
    self_overlap,
)
from cbp.collision.convex_kernels.support import PlacedConvex

__all__ = [
    "BOX",
    "CAPSULE",
    "CONVEX",
    "CYLINDER",
    "EPA_TOLERANCE",
    "FAILED",
    "GJK_TOLERANCE",
    "SPHERE",
    "UNSUPPORTED",
    "ConvexShapes",
    "LocalBounds",
    "Obstacles",
    "Placed",
    "PlacedConvex",
    "RobotTable",
    "SelfPairs",
    "Table",
    "compile_convex_kernels",
    "contact_buffers",
    "declared_contacts",
    "fields",
    "obstacle_contacts",
    "pack_shapes",
    "packed_robot",
    "pair_distance",
    "placed_robot",
    "self_contacts",
    "self_overlap",
]
