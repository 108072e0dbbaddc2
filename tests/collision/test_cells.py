"""The compiled cell queries against brute force: face grids, candidates, normals."""

from __future__ import annotations

import copy
import math

import coal
import numpy as np
import pinocchio as pin
import pytest

from cbp.collision import (
    CollisionWorld,
    MetaballRefiner,
    OccupancyEnvironment,
    RobotGeometry,
)
from cbp.collision.cell_index import CellIndex
from cbp.collision.cell_kernels import (
    EXACT_WITHIN,
    VALUE_UNIT,
    Contacts,
    cell_hits,
    face_grid,
    occupied_bits,
    spread_contacts,
)
from cbp.collision.contacts import ContactSet
from cbp.collision.geometry import LinkShape
from cbp.collision.shape_table import (
    DIRECTIONS,
    FACE_GRID_STEP,
    CellContactQuery,
    ShapeTable,
    face_grid_step,
)
from cbp.state import RobotState
from cbp.testing import sample_configurations

CELL = 0.01
#: The largest distance from a point to its nearest face-grid point [m].
SLACK = 0.5 * math.sqrt(3.0) * FACE_GRID_STEP


@pytest.fixture(scope="module")
def geometry(robots) -> RobotGeometry:
    return RobotGeometry(robots["panda"])


def _shell(centre: np.ndarray, half: float, cell: float = CELL) -> np.ndarray:
    """The cells on the surface of a cube (a map of a box seen from all sides)."""
    n = round(2 * half / cell)
    ijk = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    surface = ijk[((ijk == 0) | (ijk == n - 1)).any(axis=1)]
    return centre - half + (surface + 0.5) * cell


def _two_boxes() -> np.ndarray:
    """The surface cells of two boxes in the Panda's workspace."""
    return np.concatenate(
        [
            _shell(np.array([0.45, 0.0, 0.35]), 0.12),
            _shell(np.array([0.3, 0.25, 0.6]), 0.08),
        ]
    )


def _candidates_at_random_poses(
    geometry: RobotGeometry, robot, cells: np.ndarray, margin: float, seed: int
):
    """(placements, ShapeTable.candidates) of the Panda at 12 random poses."""
    index = CellIndex(cells, CELL)
    table = ShapeTable.build(geometry.shapes, margin + 0.5 * CELL)
    model = geometry.geometry_model()
    data = pin.GeometryData(model)
    for q in sample_configurations(robot, np.random.default_rng(seed), 12):
        state = RobotState(robot, q)
        pin.updateGeometryPlacements(robot.model, state.data, model, data)
        placements = list(data.oMg)
        yield placements, table.candidates(index, placements, margin)


def _brute_force(
    shapes: list[LinkShape],
    placements: list[pin.SE3],
    cells: np.ndarray,
    margin: float,
    half: float,
) -> dict[tuple[int, int], float]:
    """Closest distance per (shape, group), over all faces, in numpy."""
    best: dict[tuple[int, int], float] = {}
    for s, (shape, M) in enumerate(zip(shapes, placements, strict=True)):
        if isinstance(shape.shape, coal.Capsule):
            frame = M
            r, h = shape.shape.radius, shape.shape.halfLength
            lower, upper = np.array([-r, -r, -h - r]), np.array([r, r, h + r])
        else:
            frame = M * shape.placement.inverse()
            lower, upper = shape.lower, shape.upper
        local = (cells - frame.translation).dot(frame.rotation)
        grow = margin + half
        local = local[np.all((local > lower - grow) & (local < upper + grow), 1)]
        if isinstance(shape.shape, coal.Capsule):
            axis = np.zeros_like(local)
            axis[:, 2] = np.clip(local[:, 2], -h, h)
            offset = local - axis
            length = np.linalg.norm(offset, axis=1)
            depth = length - r
            group = (offset / length[:, None]).dot(DIRECTIONS.T).argmax(axis=1)
        else:
            excess = local.dot(shape.planes[:, :3].T) - shape.planes[:, 3]
            group = excess.argmax(axis=1)
            depth = excess.max(axis=1)
        for g, d in zip(group, depth - half, strict=True):
            if d < margin:
                best[s, int(g)] = min(best.get((s, int(g)), math.inf), float(d))
    return best


def _points_in_hull_boxes(geometry: RobotGeometry, table: ShapeTable, seed: int):
    """(shape index, shape, 20,000 random points in its grown box) per hull."""
    rng = np.random.default_rng(seed)
    for s, shape in enumerate(geometry.shapes):
        if isinstance(shape.shape, coal.Capsule):
            continue
        yield s, shape, rng.uniform(table.lower[s], table.upper[s], size=(20000, 3))


@pytest.mark.parametrize("reach", [0.07, 0.25])
def test_face_grid_gives_the_largest_excess_within_a_bound(geometry, reach) -> None:
    """Points measured through the face grid against all of a hull's faces.

    The grid picks the largest face exactly away from ridges between small faces;
    near them it takes a neighbour's excess, a little smaller (never larger). A
    long reach's coarser grid keeps that, within a bound as much coarser.
    """
    step = face_grid_step(reach)
    table = ShapeTable.build(geometry.shapes, reach, step)
    errors = []
    for s, shape, points in _points_in_hull_boxes(geometry, table, seed=3):
        excess = points.dot(shape.planes[:, :3].T) - shape.planes[:, 3]
        depth, face = table.hull_excess(s, points)
        np.testing.assert_allclose(
            depth, excess[np.arange(len(points)), face], atol=1e-12
        )
        errors.append(excess.max(axis=1) - depth)
    error = np.concatenate(errors)
    assert error.min() > -1e-12  # never more than the largest excess
    assert np.mean(error < 1e-12) > 0.99  # exact almost everywhere
    assert error.max() < 1e-3 * step / FACE_GRID_STEP  # 1 mm near ridges (fine grid)


def test_far_points_are_measured_on_one_face_from_below(geometry) -> None:
    """Beyond EXACT_WITHIN a point's excess is over its nearest grid point's face.

    A lower bound of the largest excess (never farther), within two grid steps'
    reach, and exact for most points.
    """
    table = ShapeTable.build(geometry.shapes, 0.07)
    errors = []
    for s, shape, points in _points_in_hull_boxes(geometry, table, seed=4):
        exact = (points.dot(shape.planes[:, :3].T) - shape.planes[:, 3]).max(axis=1)
        full, _ = table.hull_excess(s, points)
        depth, face = table.hull_excess(s, points, EXACT_WITHIN)
        near = full < EXACT_WITHIN
        # Within the band, as measured in full; beyond it, on one face.
        np.testing.assert_array_equal(depth[near], full[near])
        far = depth >= EXACT_WITHIN
        assert np.all(far | near)
        excess = points.dot(shape.planes[:, :3].T) - shape.planes[:, 3]
        np.testing.assert_allclose(
            depth[far], excess[np.arange(len(points)), face][far], atol=1e-12
        )
        errors.append(exact[far] - depth[far])
    error = np.concatenate(errors)
    assert error.min() > -1e-12  # never farther than the largest excess
    assert error.max() < 2 * SLACK
    assert np.mean(error < 1e-12) > 0.75  # the nearest point's face, mostly
    assert np.quantile(error, 0.99) < 2e-3


def test_a_point_outside_the_grown_box_is_refused(geometry) -> None:
    """The face grid covers the grown box and no more: nothing is read past it."""
    table = ShapeTable.build(geometry.shapes, 0.07)
    s = next(s for s, *_ in _points_in_hull_boxes(geometry, table, seed=0))
    inside = 0.5 * (table.lower[s] + table.upper[s])
    table.hull_excess(s, inside[None])
    outside = inside.copy()
    outside[2] = table.upper[s, 2] + 1e-3
    with pytest.raises(ValueError, match="grown box"):
        table.hull_excess(s, np.array([inside, outside]))


def test_grid_values_bound_the_excess_from_below(geometry) -> None:
    """The quick reject's values: the excess at each grid point, rounded down."""
    table = ShapeTable.build(geometry.shapes, 0.065)
    for s, shape in enumerate(geometry.shapes):
        if table.kind[s] != 0:
            continue
        dims = table.grid_dims[s]
        axes = [
            table.grid_origin[s, k] + table.step * np.arange(dims[k]) for k in range(3)
        ]
        points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        excess = (points.dot(shape.planes[:, :3].T) - shape.planes[:, 3]).max(axis=1)
        grid = slice(table.grid_start[s], table.grid_start[s + 1])
        bound = table.values[grid] * VALUE_UNIT
        assert np.all(bound <= np.maximum(excess, 0.0) + 1e-6), shape.name
        tight = (excess > 0) & (excess < 0.25)
        assert np.all(bound[tight] > excess[tight] - VALUE_UNIT - 1e-6), shape.name


def test_candidates_match_brute_force_on_the_panda(geometry, robots) -> None:
    """Per shape and face (or direction), the closest cell within the margin."""
    shapes = geometry.shapes
    margin, half = 0.06, 0.5 * CELL
    cells = _two_boxes()
    found_any = 0
    for placements, found in _candidates_at_random_poses(
        geometry, robots["panda"], cells, margin, seed=5
    ):
        shape, centre, outward, distance = found
        expected = _brute_force(shapes, placements, cells, margin, half)
        got = {}
        on_map = {tuple(c) for c in np.round(cells, 9)}
        for s, c, n, d in zip(shape, centre, outward, distance, strict=True):
            assert tuple(np.round(c, 9)) in on_map
            assert abs(np.linalg.norm(n) - 1.0) < 1e-9
            got.setdefault(int(s), []).append(float(d))
        # The same shapes have cells near them, at the same closest distance.
        exp_by_shape: dict[int, float] = {}
        for (s, _), d in expected.items():
            exp_by_shape[s] = min(exp_by_shape.get(s, math.inf), d)
        assert set(got) == set(exp_by_shape)
        for s, ds in got.items():
            assert min(ds) <= exp_by_shape[s] + 1e-9  # never farther
            if exp_by_shape[s] < EXACT_WITHIN:  # measured in full
                assert min(ds) == pytest.approx(exp_by_shape[s], abs=2e-3)
            else:  # a lower bound: two grid steps' reach at most
                assert min(ds) > exp_by_shape[s] - 2 * SLACK - 1e-9
            assert max(ds) < margin
        found_any += len(shape)
    assert found_any > 20


def test_far_cells_change_nothing(geometry, robots) -> None:
    """A map that also holds cells far away (bigger bricks) gives the same contacts."""
    robot = robots["panda"]
    state = RobotState(robot, robot.home())
    near = _shell(np.array([0.45, 0.0, 0.45]), 0.1)
    far = np.stack(np.meshgrid(*[np.arange(200) * CELL] * 2), -1).reshape(-1, 2)
    far = np.c_[far + 40.0, np.full(len(far), 0.005)]  # 40 m away, a 2 m floor
    model = geometry.geometry_model()
    data = pin.GeometryData(model)
    pin.updateGeometryPlacements(robot.model, state.data, model, data)
    placements = list(data.oMg)
    table = ShapeTable.build(geometry.shapes, 0.065)
    small, large = CellIndex(near, CELL), CellIndex(np.r_[far, near], CELL)
    assert large.brick > small.brick  # the table had to grow its bricks
    a = table.candidates(small, placements, 0.06)
    b = table.candidates(large, placements, 0.06)
    assert len(a.shape) > 0
    # Cells tied in distance may be visited in another order: compare distances.
    sa, sb = np.lexsort((a[3], a[0])), np.lexsort((b[3], b[0]))
    np.testing.assert_array_equal(a[0][sa], b[0][sb])
    np.testing.assert_allclose(a[3][sa], b[3][sb], atol=1e-12)


def test_bricks_of_places_find_what_the_cells_find(geometry, robots) -> None:
    """Testing a brick's 64 places at once gives the per-cell test's contacts.

    The cells are given shuffled (the index puts each brick's in place order);
    the same index without its place bits is read cell by cell.
    """
    robot = robots["panda"]
    rng = np.random.default_rng(4)
    cells = np.r_[
        _shell(np.array([0.45, 0.0, 0.45]), 0.1),
        _shell(np.array([0.2, 0.3, 0.6]), 0.06),
    ]
    index = CellIndex(cells[rng.permutation(len(cells))], CELL)
    assert index.brick == 4
    # Each brick's cells in place order, its bits set where they are.
    for b in np.flatnonzero(np.diff(index.start))[:50]:
        run = index.centres[index.start[b] : index.start[b + 1]]
        ijk = np.floor((run - index.origin) / CELL).astype(int) % 4
        place = (ijk[:, 0] * 4 + ijk[:, 1]) * 4 + ijk[:, 2]
        assert (np.diff(place) > 0).all()
        assert int(index.slots[b]) == sum(1 << int(p) for p in place)
    per_cell = copy.copy(index)
    per_cell.__dict__.pop("bricks", None)
    per_cell.slots = np.zeros(0, dtype=np.uint64)
    table = ShapeTable.build(geometry.shapes, 0.065)
    model = geometry.geometry_model()
    data = pin.GeometryData(model)
    compared = 0
    for q in sample_configurations(robot, np.random.default_rng(1), 6):
        state = RobotState(robot, q)
        pin.updateGeometryPlacements(robot.model, state.data, model, data)
        a = table.candidates(index, list(data.oMg), 0.06)
        b = table.candidates(per_cell, list(data.oMg), 0.06)
        for got, want in zip(a, b, strict=True):
            np.testing.assert_allclose(got, want, atol=1e-12)
        compared += len(a.shape)
    assert compared > 20


def test_cells_given_twice_are_read_one_by_one() -> None:
    """Two centres in one cell: no place bits (one bit per place), same cells."""
    cells = np.array([[0.005, 0.005, 0.005], [0.015, 0.005, 0.005]])
    index = CellIndex(np.r_[cells, cells[:1]], CELL)
    assert len(index.slots) == 0
    assert len(index) == 3


def test_occupied_bits_mark_the_non_empty_bricks() -> None:
    """Bit z % 64 of word z // 64 of a column, for columns of several words."""
    rng = np.random.default_rng(2)
    dims = np.array([3, 4, 150])  # three words per column
    counts = rng.integers(0, 3, size=int(np.prod(dims))) * (rng.random(1800) < 0.2)
    start = np.r_[0, np.cumsum(counts)].astype(np.int64)
    bits = occupied_bits(start, dims)
    assert bits.shape == (12, 3)
    assert bits.dtype == np.uint64
    for column in range(12):
        for z in range(int(dims[2])):
            on = bool((int(bits[column, z // 64]) >> (z % 64)) & 1)
            assert on == (counts[column * 150 + z] > 0)


def test_a_tall_map_is_searched_over_its_whole_height(geometry, robots) -> None:
    """Columns of more than 64 bricks: cells above the 64th brick are found."""
    robot = robots["panda"]
    state = RobotState(robot, robot.home())
    model = geometry.geometry_model()
    data = pin.GeometryData(model)
    pin.updateGeometryPlacements(robot.model, state.data, model, data)
    placements = list(data.oMg)
    hand = max(
        (s for s, shape in enumerate(geometry.shapes) if shape.link == "panda_hand"),
        key=lambda s: geometry.shapes[s].radius,
    )
    above = placements[hand].translation + np.array([0.0, 0.0, 0.13])
    # A box over the hand, and a cell 2.57 m below: the box's bottom in brick
    # 64 of its column, the first of a column's second word of bits, with the
    # shapes below it reaching down into the first word.
    box = _shell(above + np.array([0.0, 0.0, 0.1]), 0.1)
    cells = np.r_[box, np.c_[np.zeros((1, 2)), [[above[2] - 2.57]]]]
    index = CellIndex(cells, CELL)
    bottom = np.floor((box[:, 2].min() - index.origin[2]) / (CELL * index.brick))
    assert bottom == 64
    table = ShapeTable.build(geometry.shapes, 0.065)
    found = table.candidates(index, placements, 0.06)
    expected = _brute_force(geometry.shapes, placements, cells, 0.06, 0.5 * CELL)
    assert expected  # shapes near the box at the top
    assert set(found.shape.tolist()) == {s for s, _ in expected}


def test_metaball_normals_match_the_formula() -> None:
    """The compiled refinement against the field's gradient written out in numpy."""
    rng = np.random.default_rng(1)
    cells = _shell(np.zeros(3), 0.1)
    index = CellIndex(cells, CELL)
    refiner = MetaballRefiner()
    points = cells[rng.choice(len(cells), 50)]
    raw = points / np.linalg.norm(points, axis=1, keepdims=True)
    refined = refiner.refine(index, points, raw)
    radius = refiner.radius_cells * CELL
    for p, n, r in zip(points, raw, refined, strict=True):
        at = p + refiner.offset_cells * CELL * n
        diff = at - cells
        d2 = np.einsum("ij,ij->i", diff, diff)
        inside = d2 <= radius**2
        s = 1.0 - d2[inside] / radius**2
        grad = -(6.0 / radius**2) * ((s**2)[:, None] * diff[inside]).sum(axis=0)
        np.testing.assert_allclose(r, -grad / np.linalg.norm(grad), atol=1e-12)


def test_spread_contacts_keeps_distinct_directions() -> None:
    """The closest per shape first; a near twin is dropped, a new direction kept."""
    shape = np.array([0, 0, 0, 0, 1], dtype=np.intp)
    distance = np.array([0.03, 0.01, 0.011, 0.02, 0.05])
    normal = np.array(
        [[1, 0, 0], [0, 0, 1], [0, 0, 1], [1, 0, 0], [0, 1, 0]], dtype=float
    )
    point = np.array([[0, 0, 0], [0, 0, 0], [0.005, 0, 0], [0.1, 0, 0], [0, 0, 0]])
    keep = np.empty(5, dtype=np.intp)
    order = np.lexsort((distance, shape))
    n = spread_contacts(order, shape, normal, point, 2, math.cos(0.4), 1e-4, keep)
    # Shape 0: 1 (closest); 2 is its twin (same normal, 5 mm away); 3 is kept
    # (another direction); 0 would be a third. Shape 1: its only contact.
    assert keep[:n].tolist() == [1, 3, 4]


def test_cell_hits_reduce_as_the_general_contact_reduction(geometry, robots) -> None:
    """The compiled reduction of cell candidates keeps what keep_closest keeps."""
    margin, half = 0.06, 0.5 * CELL
    compared = 0
    for _, found in _candidates_at_random_poses(
        geometry, robots["panda"], _two_boxes(), margin, seed=9
    ):
        shape, centre, outward, distance = found
        for per_shape, angle, spacing in ((3, 25.0, 2 * CELL), (1, 0.0, 0.0)):
            expected = ContactSet.obstacles(
                shape,
                centre - (distance + half)[:, None] * outward,
                centre - half * outward,
                -outward,
                distance,
            ).keep_closest(per_shape, angle, spacing)
            got = cell_hits(
                found, half, per_shape, math.cos(math.radians(angle)), spacing**2
            )
            fields = ("shape", "point", "other_point", "normal", "distance")
            for name, array in zip(fields, got, strict=True):
                np.testing.assert_allclose(
                    array, getattr(expected, name), atol=1e-12, err_msg=name
                )
            compared += len(expected)
    assert compared > 20


def test_one_call_gives_what_the_steps_give(geometry, robots) -> None:
    """ShapeTable.contacts: candidates, cell_hits and the metaball, in one call."""
    margin, half = 0.06, 0.5 * CELL
    cells = _two_boxes()
    index = CellIndex(cells, CELL)
    table = ShapeTable.build(geometry.shapes, margin + half)
    refiner = MetaballRefiner()
    refine = (refiner.radius_cells * CELL, refiner.offset_cells * CELL)
    cos_max, spacing2 = math.cos(math.radians(25.0)), (2 * CELL) ** 2
    compared = 0
    for placements, found in _candidates_at_random_poses(
        geometry, robots["panda"], cells, margin, seed=5
    ):
        hits = cell_hits(found, half, 3, cos_max, spacing2)
        refined = refiner.refine(index, hits.obstacle, hits.normal)
        for option, normal in ((None, hits.normal), (refine, refined)):
            got = table.contacts(
                index, placements, margin, 3, cos_max, spacing2, option
            )
            for name in ("shape", "robot", "obstacle", "distance"):
                np.testing.assert_array_equal(
                    getattr(got, name), getattr(hits, name), err_msg=name
                )
            np.testing.assert_allclose(got.normal, normal, atol=1e-12)
            # The query bound once answers the same, call after call.
            query = CellContactQuery(table, index, margin, 3, cos_max, spacing2, option)
            for again in (query(placements), query(placements)):
                for name in Contacts._fields:
                    np.testing.assert_array_equal(
                        getattr(again, name), getattr(got, name), err_msg=name
                    )
        compared += len(hits.shape)
    assert compared > 20


def test_occupancy_query_uses_every_shape_kind(robots) -> None:
    """Capsule-approximated links find the same box as hulls, at the same distance."""
    robot = robots["panda"]
    state = RobotState(robot, robot.home())
    for approximation in ("hull", "capsule"):
        geometry = RobotGeometry(robot, approximation=approximation)
        hand = max(
            (s for s in geometry.shapes if s.link == "panda_hand"),
            key=lambda s: s.radius,
        )
        M = hand.world_placement(state)
        below = M.translation - [0.0, 0.0, hand.radius + 0.03]
        cells = _shell(below - [0, 0, 0.1], 0.1)
        env = OccupancyEnvironment(cells, CELL)
        hits = env.query(CollisionWorld(geometry).placed(state), 0.08, 3)
        assert len(hits) > 0
        assert np.all(hits.distance < 0.08)
        # Witness points are one distance apart, along the normal.
        gap = hits.point - hits.other_point
        np.testing.assert_allclose(
            np.einsum("ij,ij->i", gap, hits.normal), hits.distance, atol=1e-9
        )


def test_a_map_query_follows_its_settings(geometry, robots) -> None:
    """The query a map keeps is bound again when the margin, count or refiner change."""
    robot = robots["panda"]
    state = RobotState(robot, robot.home())
    placed = CollisionWorld(geometry).placed(state)
    env = OccupancyEnvironment(_two_boxes(), CELL, MetaballRefiner())
    few = env.query(placed, 0.3, 1)
    many = env.query(placed, 0.3, 3)
    assert len(many) > len(few) == len(set(few.shape.tolist()))
    env.refiner = None  # the hulls' face normals, unrefined
    raw = env.query(placed, 0.3, 3)
    np.testing.assert_array_equal(raw.point, many.point)
    assert np.abs(raw.normal - many.normal).max() > 1e-3
    near = env.query(placed, 0.1, 3)
    assert len(near) < len(many)
    assert np.all(near.distance < 0.1)


def test_a_world_prepares_the_snapshots_it_takes(robots) -> None:
    """Packing and compiling happen in set_environment, not in the first query."""
    from cbp.collision.cell_kernels import candidates

    geometry = RobotGeometry(robots["panda"])  # new shapes: nothing cached yet
    world = CollisionWorld(geometry)
    env = OccupancyEnvironment(_shell(np.array([0.5, 0.0, 0.3]), 0.05), CELL)
    key = (tuple(id(s) for s in geometry.shapes), world.margin(env) + 0.5 * CELL)
    assert ShapeTable.kept(geometry.shapes, key[1]) is None
    world.set_environment(env)
    assert ShapeTable.kept(geometry.shapes, key[1]) is not None
    assert candidates.signatures  # compiled, or loaded from the cache


def test_queries_run_the_kernels_compiled_beforehand() -> None:
    """After the warm-up, queries on both kinds of world compile nothing more.

    In a fresh process: a kernel compiled for other array layouts than the ones
    queries pass would be compiled again in the control loop's first query.
    """
    import subprocess
    import sys

    script = """
from cbp.collision import broad, cell_kernels as cells
from cbp.collision.shape_table import compile_kernels
from benchmarks.bench import _cat_step, _near_board, _shelf_octree_world, SCENARIOS
from cbp.scenario import load_scenario
compile_kernels()
kernels = [cells.candidates, cells.metaball_normals, cells.spread_contacts,
           cells.reduce_cells, broad.shape_bounds, broad.near_objects,
           broad.near_pairs]
before = [len(k.signatures) for k in kernels]
boards = load_scenario(SCENARIOS / "cat_boards.yaml")
boards.q0[:] = _near_board(boards)
step, world = _cat_step(boards)
for i in range(40):
    step(i)
octree, q = _shelf_octree_world()
assert len(octree.check(q).contacts) > 0
after = [len(k.signatures) for k in kernels]
assert before == after, (before, after)
# Compiled when an engine and a contact constraint are built: one layout each,
# whatever the environment the contacts come from.
from cbp.collision import OccupancyEnvironment
from cbp.collision.rows import contact_jacobian_rows
from cbp.qp import fill_qp
shelf = load_scenario(SCENARIOS / "cat_shelf_retreat.yaml")
shelf.world_for_run().set_environment(octree.environment)
step, world = _cat_step(shelf)
for i in range(10):
    step(i)
assert len(world.check(shelf.q0).contacts) > 0
assert len(fill_qp.signatures) == 1, fill_qp.signatures
from cbp.spatial import pose_error_into
assert len(pose_error_into.signatures) == 1, pose_error_into.signatures
assert len(contact_jacobian_rows.signatures) == 1, contact_jacobian_rows.signatures
"""
    run = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr[-2000:]


def test_face_grid_kernel_matches_the_float32_product(geometry) -> None:
    """The compiled face grid gives the faces and excesses of a float32 argmax."""
    shape = next(s for s in geometry.shapes if not isinstance(s.shape, coal.Capsule))
    origin = shape.lower - 0.08
    dims = np.ceil((shape.upper - shape.lower + 0.16) / FACE_GRID_STEP).astype(np.int64)
    axes = [origin[k] + FACE_GRID_STEP * np.arange(dims[k]) for k in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    excess = points.astype(np.float32).dot(shape.plane_normals_t) - shape.plane_offsets
    faces = np.empty(len(points), dtype=np.int16)
    values = np.empty(len(points), dtype=np.float32)
    face_grid(
        np.ascontiguousarray(shape.plane_normals_t.T),
        shape.plane_offsets,
        origin,
        dims,
        FACE_GRID_STEP,
        faces,
        values,
    )
    np.testing.assert_allclose(values, excess.max(axis=1), atol=1e-6)
    picked = excess[np.arange(len(points)), faces]
    np.testing.assert_allclose(picked, excess.max(axis=1), atol=1e-6)
