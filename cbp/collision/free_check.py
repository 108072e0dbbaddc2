# SPDX-License-Identifier: Apache-2.0
"""The planners' yes-or-no checks: is a configuration free, is a straight motion.

A sampling planner or an IK search asks thousands of times whether a
configuration is free and needs no contacts. Against declared objects, one
pinocchio call answers (:class:`~cbp.collision.checker.FreeSpaceChecker`);
against an occupancy map with the compiled narrow phase, one compiled pass
over the map's dense grid (:class:`MapCheck`), then one over the robot's own
pairs. A motion is checked at configurations close enough that the padded
links cannot pass an obstacle between two of them
(:class:`~cbp.collision.motion.SweepBound`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cbp.collision.cell_kernels import BlockedCells, any_cell_nearer
from cbp.collision.checker import FreeSpaceChecker
from cbp.collision.convex_kernels import RobotTable, self_overlap
from cbp.collision.environment import Environment
from cbp.collision.geometry import RobotGeometry
from cbp.collision.map_environment import BlockedGrid
from cbp.collision.motion import SweepBound
from cbp.collision.objects import PrimitiveEnvironment
from cbp.collision.settings import CollisionSettings
from cbp.collision.shape_table import ShapeTable
from cbp.robot import FloatArray, IntArray
from cbp.state import RobotState

__all__ = ["FreeCheck", "MapCheck", "blocked_cells"]


#: :attr:`CollisionWorld.sweep_step` when the links are not padded [m].
_UNPADDED_SWEEP_STEP = 0.002


def blocked_cells(blocked: BlockedGrid) -> BlockedCells:
    """A map's obstacle cells and their shell, for the compiled free check.

    A cell is in the shell unless its six neighbours are all obstacle cells
    (the grid's border cells always are); a brick of 4 x 4 x 4 cells is
    marked when it holds one.
    """
    solid = np.ascontiguousarray(blocked.mask, dtype=bool)
    inner = solid.copy()
    inner[0, :, :] = inner[-1, :, :] = False
    inner[:, 0, :] = inner[:, -1, :] = False
    inner[:, :, 0] = inner[:, :, -1] = False
    middle = inner[1:-1, 1:-1, 1:-1]
    middle &= solid[:-2, 1:-1, 1:-1]
    middle &= solid[2:, 1:-1, 1:-1]
    middle &= solid[1:-1, :-2, 1:-1]
    middle &= solid[1:-1, 2:, 1:-1]
    middle &= solid[1:-1, 1:-1, :-2]
    middle &= solid[1:-1, 1:-1, 2:]
    shell = solid & ~inner
    nx, ny, nz = (-(-n // 4) * 4 for n in shell.shape)
    padded = np.zeros((nx, ny, nz), dtype=bool)
    padded[: shell.shape[0], : shell.shape[1], : shell.shape[2]] = shell
    bricks = np.asarray(
        padded.reshape(nx // 4, 4, ny // 4, 4, nz // 4, 4).any(axis=(1, 3, 5))
    )
    return BlockedCells(
        solid, shell, bricks, np.asarray(blocked.lower, dtype=float), blocked.cell
    )


@dataclass(frozen=True)
class MapCheck:
    """What :meth:`FreeCheck.is_free` needs against one map snapshot.

    Attributes:
        blocked: the snapshot's dense grid.
        cells: its obstacle cells and their shell (:func:`blocked_cells`).
        table: the robot's shapes as the cell kernels read them.
        nearer: how near a cell's centre may come to a shape [m].
        order: the order the shapes are tried in, the last one found too near
            first (kept from one snapshot to the next).
    """

    blocked: BlockedGrid
    cells: BlockedCells
    table: ShapeTable
    nearer: float
    order: IntArray


class FreeCheck:
    """Whether configurations and straight motions are free, for planners and IK.

    Args:
        geometry: the robot's shapes and self pairs.
        settings: the narrow phase, self-collision and the penetration
            tolerance.
        padding: distance added around every robot shape [m].
        table: the robot's shapes as the convex kernels read them (its
            checked self pairs).
        centres: the shapes' bounding-sphere centres in their own frames
            (n, 3) [m].
        fixed: which shapes no joint moves (n,) (a fixed base: not tried
            against a map).
        frames: the shapes' world placements (n, 4, 4) at a state (the
            world's :meth:`~cbp.collision.world.CollisionWorld.shape_frames`).

    Not thread-safe, as the world that owns it.
    """

    def __init__(
        self,
        geometry: RobotGeometry,
        settings: CollisionSettings,
        padding: float,
        table: RobotTable,
        centres: FloatArray,
        fixed: np.ndarray,
        frames: Callable[[RobotState], FloatArray],
    ) -> None:
        """Keep the parts; the checkers are built on first use."""
        self.geometry = geometry
        self.settings = settings
        self.padding = padding
        self._table = table
        self._centres = centres
        self._fixed = fixed
        self._frames = frames
        self._state = RobotState(geometry.robot)
        self._free_space: FreeSpaceChecker | None = None
        #: The check against a map, per snapshot.
        self._map_check: MapCheck | None = None
        #: Where the self check starts each pair's GJK.
        self._free_guess = np.zeros((len(table.first), 5))

    @functools.cached_property
    def sweep(self) -> SweepBound:
        """How far the robot's shapes move along joint-space segments.

        Raises ValueError (on first use) for a robot with joints other than
        revolute and prismatic ones.
        """
        return SweepBound(self.geometry)

    @property
    def sweep_step(self) -> float:
        """The most a motion's checked configurations may be apart [m].

        By :attr:`sweep`'s bound: the padding, so that the unpadded robot
        keeps half of it between them (:mod:`cbp.collision.motion`); 2 mm
        when the links are not padded (then it may touch by up to 1 mm).
        """
        return self.padding if self.padding > 0 else _UNPADDED_SWEEP_STEP

    def motion_free(
        self, a: FloatArray, b: FloatArray, is_free: Callable[[FloatArray], bool]
    ) -> bool:
        """Whether the straight joint-space motion from ``a`` to ``b`` is free.

        ``b``, then the configurations :attr:`sweep` places between them
        :attr:`sweep_step` apart, in order, are checked by ``is_free`` up to
        the first that is not free; ``a`` is not (the motion starts there). A
        motion that ends in collision is refused at its first check.
        """
        if not is_free(b):
            return False
        return all(is_free(q) for q in self.sweep.between(a, b, self.sweep_step))

    def is_free(self, q: FloatArray, environment: Environment) -> bool:
        """Whether ``q`` is collision-free against ``environment``.

        Against declared objects, the same answer as ``check(q).penetration ==
        0``, without the contacts, in one pinocchio call
        (:class:`~cbp.collision.checker.FreeSpaceChecker`). Against an
        occupancy map, by the rule CAT's step validation uses: a padded shape
        may reach ``collision.penetration_tolerance`` plus half a cell into the
        map's cells inflated by half a cell (that is, the tolerance into the
        cells themselves). Space no camera has seen hugs the padded shapes of
        a robot that has held it, so a stricter rule would find no
        configuration near the arm free, and the planners could not plan where
        CAT can move. With the compiled narrow phase the map's cells are
        measured as CAT's step validation measures them, in one compiled pass
        over the dense grid that stops at the first cell too near
        (:func:`~cbp.collision.cell_kernels.any_cell_nearer`, the shape last
        found too near tried first), then the robot's own pairs in another
        (:func:`~cbp.collision.convex_kernels.self_overlap`).
        """
        blocked = getattr(environment, "blocked", None)
        if blocked is not None and self.settings.narrow_phase == "compiled":
            return self._free_in_map(np.asarray(q, dtype=float), blocked)
        checker = self._free_space
        if checker is None or checker.environment is not environment:
            checker = self._free_space = FreeSpaceChecker(
                self.geometry,
                environment,
                self.padding,
                self.settings.self_collision,
                tolerance=(
                    self.settings.penetration_tolerance + environment.resolution
                    if environment.resolution > 0.0
                    else 0.0
                ),
            )
        return checker.is_free(q)

    def _free_in_map(self, q: FloatArray, blocked: BlockedGrid) -> bool:
        """:meth:`is_free` against a map's dense grid ``blocked``."""
        if not math.isfinite(q.dot(q)):
            return False
        check = self._map_check
        if check is None or check.blocked is not blocked:
            # CAT keeps a step whose cells' distances, less the padding and
            # half a cell (the query's) and half a cell again (the map's
            # resolution), are no deeper than the tolerance plus half a cell:
            # each cell's centre at least this far from the shapes.
            nearer = (
                0.5 * blocked.cell + self.padding - self.settings.penetration_tolerance
            )
            check = self._map_check = MapCheck(
                blocked,
                blocked_cells(blocked),
                ShapeTable.for_shapes(self.geometry.shapes, nearer + blocked.cell),
                nearer,
                # Shapes no joint moves (a fixed base) are not tried: a floor
                # under the base touches it, and no motion can change that.
                np.flatnonzero(~self._fixed).astype(np.intp)
                if check is None
                else check.order,
            )
        state = self._state
        state.update(q)
        frames = self._frames(state)
        if (
            any_cell_nearer(
                check.cells,
                check.table.arrays,
                frames,
                self._centres,
                check.nearer,
                check.order,
            )
            >= 0
        ):
            return False
        if not self.settings.self_collision:
            return True
        table = self._table
        pad2 = 2.0 * self.padding
        own = self_overlap(
            frames,
            table.bounds,
            (table.first, table.second, self._free_guess, pad2, pad2),
        )
        if own < 0:  # a shape the kernels skip: coal measures the pairs
            return self._self_free.is_free(q)
        return own == 0

    @functools.cached_property
    def _self_free(self) -> FreeSpaceChecker:
        """The robot's own pairs' check by coal."""
        return FreeSpaceChecker(
            self.geometry, PrimitiveEnvironment([]), self.padding, self_collision=True
        )
