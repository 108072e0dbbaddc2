# SPDX-License-Identifier: Apache-2.0
"""The compiled loops of cell queries: robot shapes against occupied cells.

A hull's signed distance to a point is measured as in the k-d tree version this
replaced (``benchmarks/RESULTS.md``): the point's largest excess over the face
planes. Instead of all faces (200-500 per Panda link), a per-shape grid in the
shape's frame stores which face is largest at each grid point, and a cell is
measured against the faces of the eight grid points around it. That is exact
wherever one of those faces is the largest at the cell, which is everywhere but
within a grid step of a ridge between small faces; there the excess of a
neighbouring face is taken, a slightly smaller value (a test bounds it).

Most cells near a robot are far from it (in a perceived map of the shelf scene,
about 2,000 within the 6.5 cm margin per query, 200 within 2 cm), and those
need not be measured as finely: a cell whose excess over the face of its
nearest grid point already shows it beyond ``exact_within`` (2 cm,
:data:`EXACT_WITHIN`) keeps that excess. It is a lower bound (the largest excess
is at least any one face's), exact for 84 % of such cells and within 1 mm for
99 % on the Panda's hulls (``tests/collision/test_cells.py``), never more than
two grid steps' reach (13 mm) too near: far contacts may look nearer than they
are, never farther, and the contacts that stop the arm are measured in full.

The loops are compiled with numba (the per-cell work is a few dozen flops, which
numpy can only batch at the cost of many temporary arrays); they release the GIL.
They take their arrays grouped in named tuples: :class:`Bricks` (an index's,
:class:`~cbp.collision.cell_index.CellIndex`), :class:`Shapes` (a table's,
:class:`~cbp.collision.shape_table.ShapeTable`), :class:`Candidates` and
:class:`Contacts` (results).

The warm-up that compiles them (or loads them from numba's cache) is
:func:`~cbp.collision.shape_table.compile_kernels`, on a small table and index.

By what they compute: :mod:`~cbp.collision.cell_kernels.bricks` (the index's
bricks and place bits), :mod:`~cbp.collision.cell_kernels.measure` (a point's
distance to a shape, face grids), :mod:`~cbp.collision.cell_kernels.candidates`
(the cells near each shape), :mod:`~cbp.collision.cell_kernels.contacts`
(contacts from them) and :mod:`~cbp.collision.cell_kernels.nearer` (the
planners' yes-or-no check against a map).
"""

from cbp.collision.cell_kernels.bricks import (
    SLOT_BRICK,
    Bricks,
    occupied_bits,
    slot_masks,
)
from cbp.collision.cell_kernels.candidates import Candidates, candidates
from cbp.collision.cell_kernels.contacts import (
    Contacts,
    cell_contacts,
    cell_contacts_flat,
    cell_hits,
    metaball_normals,
    reduce_cells,
    spread_contacts,
)
from cbp.collision.cell_kernels.measure import (
    CAPSULE,
    EXACT_WITHIN,
    HULL,
    VALUE_UNIT,
    Shapes,
    face_grid,
    hull_excesses,
)
from cbp.collision.cell_kernels.nearer import BlockedCells, any_cell_nearer

__all__ = [
    "CAPSULE",
    "EXACT_WITHIN",
    "HULL",
    "SLOT_BRICK",
    "VALUE_UNIT",
    "BlockedCells",
    "Bricks",
    "Candidates",
    "Contacts",
    "Shapes",
    "any_cell_nearer",
    "candidates",
    "cell_contacts",
    "cell_contacts_flat",
    "cell_hits",
    "face_grid",
    "hull_excesses",
    "metaball_normals",
    "occupied_bits",
    "reduce_cells",
    "slot_masks",
    "spread_contacts",
]
