# SPDX-License-Identifier: Apache-2.0
"""How fast mapped obstacles come at the robot, from successive map snapshots.

A map knows where obstacles are, not how they move, so CAT plans against a
perceived obstacle as it is now and an obstacle pushed at the arm reaches it
before the trajectory loop answers (declared objects carry their velocity:
:class:`~cbp.collision.objects.PrimitiveEnvironment`'s ``look_ahead``).

What the map does tell: with unseen space counted as obstacle, a cell near the
robot turns into an obstacle only when something enters space a camera saw
free (a newly seen surface was unknown, an obstacle already). So the distance
from each robot shape to the map's obstacles, measured in the old and in the
new snapshot *at the same configuration*, changes only as obstacles move. An
:class:`ApproachEstimator` sums those changes per shape over a window and
reports the approach speed where the obstacles came at least two cells nearer
in it (one cell coming and going, a reading's flicker, sums to nothing; a
single cell does not count). The map updater publishes snapshots whose contact
distances are that much nearer over the executor's look-ahead, as declared
objects are measured ahead along their velocity.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from cbp.collision.contacts import ContactSet
from cbp.collision.geometry import WorldShapes
from cbp.collision.map_environment import BlockedGrid, OccupancyEnvironment
from cbp.collision.world import CollisionWorld
from cbp.perception.kernels import OCCUPIED
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = [
    "ApproachEstimator",
    "ClusterMotion",
    "MovingCluster",
    "swept_cells",
    "swept_snapshot",
]

#: The least approach over a window that counts as motion, in cells.
MIN_APPROACH_CELLS = 2.0


class ApproachEstimator:
    """Per robot shape, how fast the mapped obstacles approach it [m/s].

    Args:
        world: the collision world (its shapes, margin and contact count).
        window: the time the approach is summed over [s].
    """

    def __init__(self, world: CollisionWorld, window: float) -> None:
        """No snapshots seen yet."""
        if not window > 0:
            raise ValueError(f"window must be > 0 s, got {window}")
        self.world = world
        self.window = float(window)
        self.speeds = np.zeros(len(world.geometry.shapes))
        """The last estimate, per shape [m/s] (0 where nothing approaches)."""
        self._history: deque[tuple[float, FloatArray]] = deque()

    def update(
        self,
        t: float,
        state: RobotState,
        old: OccupancyEnvironment | None,
        new: OccupancyEnvironment,
    ) -> FloatArray:
        """Add the change from ``old`` to ``new`` at time ``t``; the speeds.

        Args:
            t: the time of the frames ``new`` took in [s].
            state: the robot at that time (kinematics computed): both snapshots
                are measured with the shapes there.
            old: the snapshot before (None at the first).
            new: the snapshot now (the same object: nothing changed).
        """
        n = len(self.speeds)
        nearer = np.zeros(n)
        if old is not None and new is not old:
            placed = self.world.placed_apart(state)
            margin = self.world.margin(new)
            per_shape = self.world.settings.contacts_per_link
            before = _nearest(old.query(placed, margin, per_shape), n)
            after = _nearest(new.query(placed, margin, per_shape), n)
            # Where both see an obstacle within the margin: an obstacle that
            # enters the margin has no earlier distance to compare.
            both = np.isfinite(before) & np.isfinite(after)
            nearer[both] = before[both] - after[both]
        history = self._history
        history.append((t, nearer))
        while history and history[0][0] <= t - self.window:
            history.popleft()
        total = np.sum([change for _, change in history], axis=0)
        least = MIN_APPROACH_CELLS * new.cell
        self.speeds = np.where(total >= least, total / self.window, 0.0)
        return self.speeds


def _nearest(contacts: ContactSet, n: int) -> FloatArray:
    """Per shape, its nearest contact's distance (inf without one)."""
    out = np.full(n, np.inf)
    np.minimum.at(out, contacts.shape, contacts.distance)
    return out


@dataclass(frozen=True)
class MovingCluster:
    """A group of touching occupied cells that moves.

    Attributes:
        cells: its cells' grid indices (n, 3).
        velocity: its velocity [m/s].
    """

    cells: np.ndarray
    velocity: FloatArray


@dataclass
class _Track:
    """One cluster followed over snapshots: its centroid's history."""

    history: deque[tuple[float, FloatArray]]
    size: int


class ClusterMotion:
    """Velocities of the mapped obstacles near the robot, cluster by cluster.

    The occupied cells within :data:`CLUSTER_REACH` of the robot's shapes are
    grouped into clusters of touching cells (26-neighbourhood, on a grid of
    twice the cell size); each cluster is matched to the one of the previous
    snapshot it overlaps most (grown by a coarse cell: a face that moved
    along its normal no longer overlaps itself), and its velocity is its
    centroid's displacement over the window.
    A cluster moves when its centroid moved at least :data:`MIN_APPROACH_CELLS`
    cells over the window (a reading's flicker does not). Unlike
    :class:`ApproachEstimator`, a moving obstacle is measured on its own, not
    through the nearest distance of each robot shape: a nearer static
    obstacle does not hide it. Clusters that touch (a box pushed along the
    table) are one cluster, and the centroid of what the cameras see of it
    moves with its visible faces.

    Args:
        grid_lower: the grid's lower corner [m].
        cell: cell size [m].
        window: the time the displacement is measured over [s].
    """

    def __init__(self, grid_lower: FloatArray, cell: float, window: float) -> None:
        """No snapshot seen yet."""
        if not window > 0:
            raise ValueError(f"window must be > 0 s, got {window}")
        self.lower = np.asarray(grid_lower, dtype=float)
        self.cell = float(cell)
        self.window = float(window)
        # The last snapshot's labels on the coarse grid, and their origin.
        self._labels: np.ndarray | None = None
        self._origin = np.zeros(3, dtype=np.intp)
        self._t = -np.inf  # the time of the last update
        self._tracks: dict[int, _Track] = {}  # by the last snapshot's label
        self.moving: list[MovingCluster] = []
        """The clusters of the last update that move."""

    def update(
        self, t: float, cells: np.ndarray, shapes: WorldShapes
    ) -> list[MovingCluster]:
        """Take the grid's cell states (``OccupancyGrid.cells``) at ``t`` [s].

        ``shapes``: the robot's shapes at ``t``, which bound the region
        looked at. Returns the clusters that move (at a time already taken,
        from another camera's frame: the clusters found then).

        Cells are grouped on a grid of twice the cell size (cells two apart
        touch; a tenth of the cost of grouping the cells themselves).
        """
        if t == self._t:  # another camera's frame of the same time
            return self.moving
        self._t = t
        lo, hi = self._region(shapes, cells.shape)
        sub = cells[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] == OCCUPIED
        fine = np.argwhere(sub) + lo  # the grid's indices
        coarse = fine // 2
        origin = lo // 2
        size = (hi + 1) // 2 - origin
        grouped = np.zeros(tuple(int(n) for n in size), dtype=bool)
        local = coarse - origin
        grouped[local[:, 0], local[:, 1], local[:, 2]] = True
        labels, count = ndimage.label(grouped, structure=np.ones((3, 3, 3), bool))
        label_of = labels[local[:, 0], local[:, 1], local[:, 2]]
        matched = self._match(labels, origin, count)
        self._labels, self._origin = labels, origin
        tracks: dict[int, _Track] = {}
        moving: list[MovingCluster] = []
        if count:
            sizes = np.bincount(label_of, minlength=count + 1)
            sums = np.stack(
                [
                    np.bincount(label_of, weights=fine[:, d], minlength=count + 1)
                    for d in range(3)
                ],
                axis=1,
            )
            order = np.argsort(label_of, kind="stable")
            bounds = np.concatenate([[0], np.cumsum(sizes)])
            for label in range(1, count + 1):
                if sizes[label] < MIN_CLUSTER_CELLS:
                    continue
                centroid = self.lower + (sums[label] / sizes[label] + 0.5) * self.cell
                track = self._tracks.get(matched.get(label, 0))
                history: deque[tuple[float, FloatArray]] = (
                    track.history if track is not None else deque()
                )
                history.append((t, centroid))
                while history and history[0][0] < t - self.window - 1e-9:
                    history.popleft()
                tracks[label] = _Track(history, int(sizes[label]))
                t0, c0 = history[0]
                moved = centroid - c0
                if (
                    t - t0 > 0
                    and np.linalg.norm(moved) >= MIN_APPROACH_CELLS * self.cell
                ):
                    members = fine[order[bounds[label] : bounds[label + 1]]]
                    moving.append(MovingCluster(members, moved / (t - t0)))
        self._tracks = tracks
        self.moving = moving
        return moving

    def _region(
        self, shapes: WorldShapes, shape: tuple[int, ...]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Index box of the cells within CLUSTER_REACH of the robot's spheres."""
        reach = shapes.radii[:, None] + CLUSTER_REACH
        lower = (shapes.centres - reach).min(axis=0)
        upper = (shapes.centres + reach).max(axis=0)
        lo = np.floor((lower - self.lower) / self.cell).astype(np.intp)
        hi = np.ceil((upper - self.lower) / self.cell).astype(np.intp)
        return np.clip(lo, 0, shape), np.clip(hi, 0, shape)

    def _match(
        self, labels: np.ndarray, origin: np.ndarray, count: int
    ) -> dict[int, int]:
        """Each new cluster's label to the last snapshot's it overlaps most.

        On the coarse grid, each cell grown by one (a face that moved along
        its normal no longer overlaps itself).
        """
        old, old_origin = self._labels, self._origin
        if old is None or not count:
            return {}
        where = np.argwhere(labels > 0)
        new_label = labels[where[:, 0], where[:, 1], where[:, 2]].astype(np.int64)
        at = where + origin - old_origin
        keys = []
        for offset in _NEIGHBOURS:
            p = at + offset
            inside = np.all((p >= 0) & (p < np.array(old.shape)), axis=1)
            hit = old[p[inside, 0], p[inside, 1], p[inside, 2]].astype(np.int64)
            keep = hit > 0
            keys.append(new_label[inside][keep] * (int(old.max()) + 1) + hit[keep])
        if not keys:
            return {}
        pairs, counts = np.unique(np.concatenate(keys), return_counts=True)
        base = int(old.max()) + 1
        best: dict[int, tuple[int, int]] = {}
        for key, n in zip(pairs.tolist(), counts.tolist(), strict=True):
            new, was = divmod(key, base)
            if n > best.get(new, (0, 0))[1]:
                best[new] = (was, n)
        return {new: was for new, (was, _) in best.items()}


def swept_cells(
    clusters: list[MovingCluster], horizon: float, cell: float
) -> np.ndarray:
    """Grid indices (n, 3) each moving cluster passes over ``horizon`` [s] ahead.

    Its cells moved along its velocity, a step of at most a cell at a time;
    the cells it holds now are not repeated.
    """
    out: list[np.ndarray] = []
    for cluster in clusters:
        travel = cluster.velocity * max(horizon, 0.0) / cell  # in cells
        steps = int(np.ceil(np.abs(travel).max()))
        for k in range(1, steps + 1):
            out.append(cluster.cells + np.round(travel * k / steps).astype(np.intp))
    if not out:
        return np.zeros((0, 3), dtype=np.intp)
    return np.unique(np.vstack(out), axis=0)


def swept_snapshot(
    mapped: OccupancyEnvironment,
    clusters: list[MovingCluster],
    horizon: float,
    lower: FloatArray,
) -> OccupancyEnvironment:
    """``mapped`` with the cells the moving clusters pass over ``horizon`` ahead.

    The swept cells join the obstacle cells (and the obstacle mask); a new
    snapshot with the same stamp, or ``mapped`` itself when nothing moves
    into free cells. ``lower``: the grid's lower corner [m].
    """
    if not clusters or mapped.blocked is None:
        return mapped
    cell = mapped.cell
    mask = mapped.blocked.mask
    ijk = swept_cells(clusters, horizon, cell)
    inside = np.all((ijk >= 0) & (ijk < np.array(mask.shape)), axis=1)
    ijk = ijk[inside]
    ijk = ijk[~mask[ijk[:, 0], ijk[:, 1], ijk[:, 2]]]
    if not len(ijk):
        return mapped
    blocked = mask.copy()
    blocked[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = True
    lower = np.asarray(lower, dtype=float)
    centres = np.vstack([mapped.centres, lower + (ijk + 0.5) * cell])
    out = OccupancyEnvironment(
        centres,
        cell,
        mapped.refiner,
        blocked=BlockedGrid(blocked, lower, cell, outside=mapped.blocked.outside),
    )
    out.stamp = mapped.stamp
    return out


#: The region clustered: cells within this of the robot's bounding spheres [m].
CLUSTER_REACH = 0.3
#: Clusters smaller than this are a reading's noise, not an obstacle.
MIN_CLUSTER_CELLS = 4
#: The 27 offsets of a cell's neighbourhood (itself included).
_NEIGHBOURS = np.array(
    [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)]
)
