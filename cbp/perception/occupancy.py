# SPDX-License-Identifier: Apache-2.0
"""An occupancy grid updated from depth frames, with the robot filtered out.

Why not OctoMap: ray-cast insertion of one 320x240 frame takes 120-250 ms on this
machine and its default clamping keeps a moved obstacle for about nine frames
(``../shared/notes/perception.md``). This grid marks hits in a dense voxel array
and clears cells by projecting them into the image: a cell the camera sees
*through* (the measured surface along its pixel is farther than the cell) gets a
miss, and ``misses_to_clear`` misses remove it. That is a few ms per frame and
clears a removed obstacle in ``misses_to_clear`` frames. The collision queries
still run on an octree (coal's), built from the occupied centres.

Robot pixels: points within the robot's padded shapes are not inserted, and their
pixels count as unknown for clearing, so the robot never clears what it hides.
"""

from __future__ import annotations

import numpy as np

from cbp.collision.environment import MetaballRefiner, OccupancyEnvironment
from cbp.collision.geometry import RobotGeometry
from cbp.perception.camera import DepthFrame
from cbp.perception.spec import PerceptionSpec
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = ["OccupancyGrid"]


class OccupancyGrid:
    """A dense voxel grid over the mapped region.

    Args:
        spec: resolution, bounds, range and clearing settings.
        geometry: the robot's shapes, for filtering it out (None: no filter).
    """

    def __init__(self, spec: PerceptionSpec, geometry: RobotGeometry | None) -> None:
        """Allocate the grid (all free)."""
        self.spec = spec
        self.cell = spec.cell_size
        self.lower = np.asarray(spec.bounds[0], dtype=float)
        upper = np.asarray(spec.bounds[1], dtype=float)
        self.shape = tuple(np.ceil((upper - self.lower) / self.cell).astype(int))
        self.occupied = np.zeros(self.shape, dtype=bool)
        self.misses = np.zeros(self.shape, dtype=np.uint8)
        self.geometry = geometry
        self.frames = 0
        self.robot_points_removed = 0

    def centres(self) -> FloatArray:
        """Centres of the occupied cells (N, 3) [m]."""
        idx = np.argwhere(self.occupied)
        return np.asarray(self.lower + (idx + 0.5) * self.cell)

    def integrate(self, frame: DepthFrame, state: RobotState | None) -> None:
        """Insert a frame's hits and clear the cells it sees through.

        Args:
            frame: the depth image.
            state: the robot at capture time, for the self-filter (None: no robot).
        """
        points, hit = frame.points()
        ranges = frame.ranges()
        camera = frame.position
        dist = np.linalg.norm(points - camera, axis=-1)
        valid = hit & (dist <= self.spec.max_range)
        robot = np.zeros_like(valid)
        if state is not None and self.geometry is not None:
            rows, cols = np.nonzero(valid)
            on_robot = self.geometry.contains(
                state, points[rows, cols], margin=self.spec.robot_margin
            )
            robot[rows[on_robot], cols[on_robot]] = True
            self.robot_points_removed += int(on_robot.sum())
        keep = valid & ~robot
        self._clear(frame, ranges, robot)
        self._insert(points[keep])
        self.frames += 1

    def _insert(self, points: FloatArray) -> None:
        idx = np.floor((points - self.lower) / self.cell).astype(np.intp)
        inside = np.all((idx >= 0) & (idx < np.array(self.shape)), axis=1)
        idx = idx[inside]
        self.occupied[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        self.misses[idx[:, 0], idx[:, 1], idx[:, 2]] = 0

    def _clear(self, frame: DepthFrame, ranges: FloatArray, robot: np.ndarray) -> None:
        idx = np.argwhere(self.occupied)
        if len(idx) == 0:
            return
        centres = self.lower + (idx + 0.5) * self.cell
        rows, cols, depth = frame.project(centres)
        seen = rows >= 0
        measured = np.full(len(idx), -np.inf)
        measured[seen] = ranges[rows[seen], cols[seen]]
        # Robot pixels are unknown: the robot may hide the cell.
        measured[seen] = np.where(
            robot[rows[seen], cols[seen]], -np.inf, measured[seen]
        )
        # Background (inf) sees through everything up to the far plane.
        measured = np.minimum(measured, frame.far)
        through = seen & (depth < measured - self.cell) & (depth > frame.near)
        hit_idx = idx[through]
        m = self.misses[hit_idx[:, 0], hit_idx[:, 1], hit_idx[:, 2]] + 1
        self.misses[hit_idx[:, 0], hit_idx[:, 1], hit_idx[:, 2]] = m
        gone = hit_idx[m >= self.spec.misses_to_clear]
        self.occupied[gone[:, 0], gone[:, 1], gone[:, 2]] = False
        self.misses[gone[:, 0], gone[:, 1], gone[:, 2]] = 0

    def environment(self) -> OccupancyEnvironment:
        """A snapshot for the collision world (brick index + octree of the centres)."""
        s = self.spec
        refiner = (
            MetaballRefiner(
                radius_cells=s.metaball_radius_cells,
                offset_cells=s.metaball_offset_cells,
            )
            if s.refine_normals
            else None
        )
        return OccupancyEnvironment(self.centres(), self.cell, refiner)

    def __repr__(self) -> str:
        """Size, resolution and occupancy."""
        return (
            f"OccupancyGrid(shape={self.shape}, cell={self.cell}, "
            f"occupied={int(self.occupied.sum())}, frames={self.frames})"
        )
