# SPDX-License-Identifier: Apache-2.0
"""Moving cells measured ahead: an obstacle that comes is met where it will be.

The map knows where a moving obstacle's leading surface is, not where it will
be when the plan made now has run. The cameras do tell *which* cells move: a
fixed camera's reading that comes nearer than the space its pixel saw free
falls in a cell something entered (:meth:`OccupancyGrid.moving_centres
<cbp.perception.occupancy.OccupancyGrid.moving_centres>`). Those cells, and
only those, are measured nearer by how far an obstacle at the assumed speed
(``perception.moving_speed``) comes over the look-ahead and the snapshot's
age, in every direction: the robot keeps clear of the whole region the
obstacle can reach by then, as speed and separation monitoring (ISO/TS 15066)
counts the separation the robot needs against an assumed approach speed.

While a moving cell is that near the robot, space no camera has seen gives
way: the snapshot's contacts are kept only with cells the newest grid holds
occupied (unknown ones, and those seen through since the snapshot, are left
out), so the arm may
retreat into its own shadow rather than be pinned between an obstacle it sees
come and space it has not seen (what gives way first: physical limits hold,
then seen obstacles, then unseen space).

Unlike the per-shape approach estimate
(:class:`~cbp.perception.motion.ApproachEstimator`), which follows each robot
shape's *nearest* obstacle, a moving cell is measured on its own: space no
camera has seen, or a static obstacle, nearer to the arm does not hide it.
"""

from __future__ import annotations

import math

import numpy as np

from cbp.collision.contacts import ContactSet
from cbp.collision.environment import NarrowPhase
from cbp.collision.geometry import LinkShape, PlacedShapes
from cbp.collision.map_environment import OccupancyEnvironment
from cbp.perception.kernels import OCCUPIED
from cbp.perception.spec import PerceptionSpec
from cbp.robot import FloatArray

__all__ = [
    "GROWTH_STEP",
    "PREPARED_LOOK_AHEAD",
    "REACH_STEP",
    "MovingCellsEnvironment",
    "frame_period",
    "moving_growth",
    "prepare_moving_tables",
    "with_moving",
]

#: The growth is rounded up to whole steps of this [m].
GROWTH_STEP = 0.01
#: The moving cells' query tables are built for reaches in whole steps of this
#: [m]: the growth follows the snapshot's age and the command period, and a
#: table for each new reach (a face grid per hull) would be built while the
#: arm needs its steps most. Measured on the generated scene moving_3 in
#: wall-clock runs: a table per centimetre of growth took 4.8-15 s of CPU
#: each, most of the planning time, while two obstacles closed on the arm.
REACH_STEP = 0.05


#: The look-ahead [s] a wall-clock run's moving cells are prepared for before
#: it starts (:func:`prepare_moving_tables`): two of the longest command
#: periods (0.133 s) and a Panda's stopping time, rounded up.
PREPARED_LOOK_AHEAD = 0.6


class _MovingCells(OccupancyEnvironment):
    """The moving cells: an environment queried at margins that change."""

    reach_step = REACH_STEP


def frame_period(spec: PerceptionSpec) -> float:
    """The slowest fixed camera's frame period [s] (0: no fixed camera).

    Only fixed cameras tell which cells something entered
    (:meth:`~cbp.perception.occupancy.OccupancyGrid.moving_centres`).
    """
    rates = [c.rate_hz for c in spec.all_cameras if c.parent is None]
    return 1.0 / min(rates) if rates else 0.0


def moving_growth(
    speed: float,
    look_ahead: float,
    age: float,
    still: float = 0.0,
    cell: float = 0.0,
    frame: float = 0.0,
) -> float:
    """How much nearer moving cells are measured [m]: 0 without a look-ahead.

    ``speed`` [m/s] over the look-ahead and the snapshot's age [s], rounded
    up to :data:`GROWTH_STEP`. An executor that plans nothing ahead (a
    look-ahead of 0: JT, a run's last stretch) measures them where they are.

    Once what moved stands still, the growth shrinks. Something that moves at
    v enters a new cell at least every ``cell`` / v seconds (its leading face
    crosses one), and the cameras see each entered cell within a frame; so
    when no cell has been entered for ``still`` seconds (before the
    snapshot's stamp), nothing seen moves faster than ``cell / still``, and
    the look-ahead is measured at that speed (at most ``speed``). What
    starts again is seen within a frame (``frame`` [s], the slowest fixed
    camera's period) and the snapshot's age: the arm keeps ``speed`` times
    that from it however long it stood, as it would from an obstacle first
    seen moving then. A moving obstacle (``still`` under ``cell / speed``)
    is measured as before: ``speed`` x (look-ahead + age). Before, a stopped
    obstacle kept the whole growth (19 cm at 0.25 m/s) for
    ``perception.shadow_hold`` (1 s) after it stopped, and the arm fled it.
    """
    if not look_ahead > 0.0 or not speed > 0.0:
        return 0.0
    moving = speed if not still > 0.0 else min(speed, cell / still)
    ahead = max(moving * look_ahead, speed * min(frame, look_ahead))
    growth = speed * max(0.0, age) + ahead
    return math.ceil(growth / GROWTH_STEP - 1e-9) * GROWTH_STEP


class MovingCellsEnvironment(OccupancyEnvironment):
    """A map snapshot whose moving cells are measured ``growth`` nearer.

    The snapshot's contacts, and the moving cells' contacts, found within the
    margin plus ``growth`` and reported ``growth`` nearer. Everything else
    (planners' checks, :meth:`inside`, the stamp) is the snapshot's.

    Attributes:
        moving: the moving cells, as an environment of their own.
        growth: how much nearer they are measured [m].
        states: the grid's cell states (live: the map's own array, which may be
            newer than the snapshot), which tell unknown cells from occupied
            ones.
        lower: the grid's lower corner [m].
    """

    moving: OccupancyEnvironment
    growth: float
    states: np.ndarray
    lower: FloatArray

    def prepare(self, shapes: list[LinkShape], margin: float) -> None:
        """Build the snapshot's table and the moving cells' (in the map's thread).

        A world prepares a snapshot before it swaps it in
        (:meth:`~cbp.collision.world.CollisionWorld.set_environment`), so a
        new reach's table is built there, not in the control loop's query.
        """
        super().prepare(shapes, margin)
        self.moving.prepare(shapes, margin + self.growth)

    def query(
        self,
        robot: PlacedShapes,
        margin: float,
        per_shape: int,
        narrow_phase: NarrowPhase = "compiled",
    ) -> ContactSet:
        """The snapshot's contacts and the moving cells' ones, ``growth`` nearer.

        With a moving cell's contact, the snapshot's contacts with unknown
        cells are left out (the module's docstring).
        """
        mapped = super().query(robot, margin, per_shape, narrow_phase)
        ahead = self.moving.query(robot, margin + self.growth, per_shape, narrow_phase)
        if not len(ahead):
            return mapped
        ahead.distance = ahead.distance - self.growth
        ahead.lead = np.full(len(ahead), self.growth)
        return ContactSet.concatenate([self._seen(mapped), ahead])

    def _seen(self, contacts: ContactSet) -> ContactSet:
        """``contacts`` with cells the newest grid holds occupied, and no others.

        The cells are looked up in the grid as it is now, which a map in its
        own thread or process has moved on from since this snapshot: a cell
        unknown in the snapshot that a camera has since seen through is free
        now. Before, such a cell was kept (it was not unknown any more), and
        the unseen space it had been held the arm while obstacles came:
        measured on the generated scene moving_3 in virtual time with the
        snapshots installed 5 frames late, 39 kN, 1110 eased QPs; with this
        rule 0 N (as without the delay), and 0 N in a wall-clock run with the
        map in its own process.
        """
        if not len(contacts):
            return contacts
        # A contact's obstacle point lies on its cell's surface toward the
        # shape: a quarter cell back along the normal is inside the cell.
        inner = contacts.other_point - 0.25 * self.cell * contacts.normal
        ijk = np.floor((inner - self.lower) / self.cell).astype(np.intp)
        shape = np.array(self.states.shape)
        inside = np.all((ijk >= 0) & (ijk < shape), axis=1)
        state = np.full(len(ijk), OCCUPIED, dtype=np.int64)  # off the grid: kept
        i = ijk[inside]
        state[inside] = self.states[i[:, 0], i[:, 1], i[:, 2]]
        keep = state == OCCUPIED
        if keep.all():
            return contacts
        return contacts.select(keep)


def prepare_moving_tables(
    shapes: list[LinkShape], margin: float, cell: float, speed: float, horizon: float
) -> list[float]:
    """Build the query tables for every reach moving cells may need; the reaches.

    Moving cells are queried at the snapshot's ``margin`` plus their growth
    (:func:`moving_growth`), whose reach is rounded up to :data:`REACH_STEP`;
    a new reach's table (a face grid per hull, 0.1-0.4 s of CPU each for a
    Panda) was built when the first obstacle set off, in the thread that
    adopts the map's snapshots. On a wall-clock run that held up the
    snapshots, and the robot was stopped for the map lagging behind the
    cameras (the generated scene moving_11: 22 of 30 runs, mostly the first
    run of a process). This builds them before the run, for growths up to
    ``speed`` times ``horizon`` [s] (a longer one still builds its table when
    it comes).

    Args:
        shapes: the robot's shapes.
        margin: the snapshots' query margin [m] (the collision world's).
        cell: the map's cell [m].
        speed: the assumed approach speed (``perception.moving_speed``) [m/s].
        horizon: the longest look-ahead plus snapshot age prepared for [s].
    """
    if not speed > 0.0:
        return []
    probe = _MovingCells(np.zeros((0, 3)), cell)
    reaches: list[float] = []
    for k in range(round(moving_growth(speed, horizon, 0.0) / GROWTH_STEP) + 1):
        growth = k * GROWTH_STEP
        if probe.table_reach(margin + growth) not in reaches:
            reaches.append(probe.table_reach(margin + growth))
            probe.prepare(shapes, margin + growth)
    return reaches


def with_moving(
    mapped: OccupancyEnvironment,
    centres: FloatArray,
    growth: float,
    states: np.ndarray,
    lower: FloatArray,
) -> OccupancyEnvironment:
    """``mapped`` with the cells at ``centres`` (N, 3) measured ``growth`` nearer.

    ``states`` and ``lower``: the grid's cell states and lower corner (see
    :class:`MovingCellsEnvironment`).

    ``mapped`` itself when no cell moves or ``growth`` is 0; else a new
    snapshot object (its users tell snapshots apart by identity) sharing the
    snapshot's cells, index and stamp.
    """
    if not len(centres) or not growth > 0.0:
        return mapped
    out = MovingCellsEnvironment.__new__(MovingCellsEnvironment)
    out.__dict__.update(mapped.__dict__)
    out.moving = _MovingCells(centres, mapped.cell, mapped.refiner)
    out.growth = float(growth)
    out.states = states
    out.lower = np.asarray(lower, dtype=float)
    return out
