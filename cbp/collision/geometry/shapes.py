# SPDX-License-Identifier: Apache-2.0
"""The robot's shapes as records: on their frames, placed in the world, packed.

A :class:`LinkShape` is one convex shape fixed on a frame of the model (an
:class:`Attachment` declares one the URDF does not hold); a query takes them
placed at one configuration (:class:`ShapePlacements`, :class:`PlacedShapes`),
the depth images' self-filter as stacked half-spaces (:class:`WorldShapes`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import coal
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from cbp.collision.geometry.hulls import face_planes, primitive_mesh
from cbp.robot import FloatArray, IntArray
from cbp.state import RobotState

__all__ = [
    "Attachment",
    "LinkShape",
    "PlacedShapes",
    "ShapePlacements",
    "WorldShapes",
]


class ShapePlacements(list[pin.SE3]):
    """The robot shapes' world placements, in shape order, also stacked.

    A list of pinocchio SE3 (what coal's distance calls take) that keeps their
    homogeneous matrices in one array, ``homogeneous`` (n, 4, 4), made once per
    query for the compiled loops that read them all.
    """

    def __init__(self, placements: list[pin.SE3]) -> None:
        """Keep the placements and stack their matrices."""
        super().__init__(placements)
        self.homogeneous: FloatArray = np.array(
            [M.homogeneous for M in placements]
        ).reshape(-1, 4, 4)


@dataclass(frozen=True)
class PlacedShapes:
    """A robot's shapes at one configuration, as environments query them.

    Attributes:
        shapes: the shapes (:attr:`~cbp.collision.geometry.RobotGeometry.shapes`).
        placements: their world placements, also stacked.
        centres: their bounding-sphere centres in the world (n, 3) [m].
        radii: their bounding-sphere radii (n,) [m].
        halves: half extents of world-aligned boxes around the shapes about
            ``centres`` (n, 3) [m], for a tighter broad phase.
    """

    shapes: list[LinkShape]
    placements: ShapePlacements
    centres: FloatArray
    radii: FloatArray
    halves: FloatArray


@dataclass(frozen=True)
class LinkShape:
    """One convex collision shape fixed on a frame of the robot.

    Attributes:
        name: the geometry's name (``<link>_<index>``).
        link: the link (frame) name that carries it.
        frame_id: index of that frame in the model.
        joint_id: the joint that moves the frame.
        placement: the shape's pose in the frame.
        shape: the coal shape.
        centre: bounding-sphere centre in the frame [m], shape (3,).
        radius: bounding-sphere radius [m].
        planes: hull half-spaces in the frame, (F, 4): ``n . x <= d`` as (n, d).
        lower: the hull's bounding-box corner, axes of the frame [m], shape (3,).
        upper: the opposite corner [m], shape (3,).
    """

    name: str
    link: str
    frame_id: int
    joint_id: int
    placement: pin.SE3
    shape: coal.ShapeBase
    centre: FloatArray
    radius: float
    planes: FloatArray
    lower: FloatArray
    upper: FloatArray

    @classmethod
    def probe(cls, name: str, shape: coal.ShapeBase) -> LinkShape:
        """A primitive on the world frame (frame 0), for studies and tests."""
        mesh = primitive_mesh(shape)
        vertices = np.asarray(mesh.vertices)
        lower, upper = vertices.min(axis=0), vertices.max(axis=0)
        centre = 0.5 * (lower + upper)
        return cls(
            name=name,
            link=name,
            frame_id=0,
            joint_id=0,
            placement=pin.SE3.Identity(),
            shape=shape,
            centre=centre,
            radius=float(np.linalg.norm(vertices - centre, axis=1).max()),
            planes=face_planes(mesh),
            lower=lower,
            upper=upper,
        )

    @functools.cached_property
    def plane_normals_t(self) -> npt.NDArray[np.float32]:
        """The face planes' normals as contiguous float32 columns, (3, F).

        For matrix products with many points: a strided slice of ``planes`` makes
        numpy skip BLAS (10x slower), and float32 is exact to 0.1 um here.
        """
        return np.ascontiguousarray(self.planes[:, :3].T, dtype=np.float32)

    @functools.cached_property
    def plane_offsets(self) -> npt.NDArray[np.float32]:
        """The face planes' offsets d (n . x <= d), float32, (F,)."""
        return np.ascontiguousarray(self.planes[:, 3], dtype=np.float32)

    def world_placement(self, state: RobotState) -> pin.SE3:
        """The shape's placement in the world at ``state``."""
        return state.data.oMf[self.frame_id] * self.placement


@dataclass(frozen=True)
class Attachment:
    """A rigid body fixed on a robot frame that the URDF does not hold.

    A mounted camera's housing, a tool: checked like the URDF's collision shapes
    (padding, contacts, self-collision with non-adjacent bodies, the depth
    images' self-filter).

    Attributes:
        name: the shape's name.
        frame: the robot frame that carries it.
        placement: its pose in that frame.
        shape: a coal primitive (box, sphere, cylinder or capsule).
    """

    name: str
    frame: str
    placement: pin.SE3
    shape: coal.ShapeBase


@dataclass(frozen=True)
class WorldShapes:
    """A robot's convex shapes placed in the world, packed for compiled loops.

    Attributes:
        planes: half-spaces ``n . x <= d`` of every shape as rows (n, d), stacked,
            (P, 4).
        plane_start: shape s's planes are rows ``plane_start[s]`` to
            ``plane_start[s + 1]``, (shapes + 1,).
        centres: bounding-sphere centres (shapes, 3) [m].
        radii: bounding-sphere radii (shapes,) [m].
        frames: the frames that carry the shapes, as homogeneous matrices
            (shapes, 4, 4).
    """

    planes: FloatArray
    plane_start: IntArray
    centres: FloatArray
    radii: FloatArray
    frames: FloatArray
