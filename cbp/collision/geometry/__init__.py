# SPDX-License-Identifier: Apache-2.0
"""The robot's collision geometry: one convex shape per URDF collision element.

Each ``<collision>`` element of the URDF becomes a :class:`LinkShape`: a coal shape
(URDF primitives as they are, meshes replaced by their convex hull, built with
trimesh since the coal wheel has no qhull), its placement on a frame of the model,
a bounding sphere for the broad phase, and the hull's half-spaces for filtering the
robot out of depth images. Padding is not baked into the shapes: every query
subtracts it from the distances, which is exactly the distance to the shape grown
by a sphere of that radius.

By concern: :mod:`~cbp.collision.geometry.robot` (a robot's shapes and self
pairs), :mod:`~cbp.collision.geometry.shapes` (the shape records),
:mod:`~cbp.collision.geometry.hulls` (meshes into hulls and planes) and
:mod:`~cbp.collision.geometry.inside` (compiled point-inside tests).
"""

from cbp.collision.geometry.hulls import fit_capsule
from cbp.collision.geometry.inside import inside_any, inside_convex, points_inside
from cbp.collision.geometry.robot import (
    UNREAD_VISUAL_EXCESS,
    RobotGeometry,
    find_ignorable_pairs,
)
from cbp.collision.geometry.shapes import (
    Attachment,
    LinkShape,
    PlacedShapes,
    ShapePlacements,
    WorldShapes,
)

__all__ = [
    "UNREAD_VISUAL_EXCESS",
    "Attachment",
    "LinkShape",
    "PlacedShapes",
    "RobotGeometry",
    "ShapePlacements",
    "WorldShapes",
    "find_ignorable_pairs",
    "fit_capsule",
    "inside_any",
    "inside_convex",
    "points_inside",
]
