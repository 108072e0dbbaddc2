"""The compiled narrow phase against two independent references: coal and python-fcl.

Random placements (seeded) of the Panda's hulls and of primitives against boxes,
spheres, cylinders, capsules and a mesh hull. What is compared:

- separated pairs (coal's distance above ``SEPARATED``): the distance within
  1e-6 m of coal's and the normal within 1e-3 rad (coal's GJK tolerance set to
  1e-10; its default stops within 1e-6 of the distance, relative). python-fcl
  0.7 stops its GJK earlier, and its tolerance cannot be set from Python: over
  30 samples of this test its distances were up to 7 cm long and its normals
  up to 0.9 rad off. Its distance is realised by a pair of points of the two
  shapes, so it bounds the true one from above: the kernel's must never
  exceed it;
- penetrating pairs (below ``-SEPARATED``): the depth within 1e-6 m of coal's
  EPA (1e-5 m against a cylinder, whose curved side both EPAs approximate to
  their tolerance) and within 1e-5 m of fcl's. Where the deepest direction is
  not unique the normals may differ, so the normal is checked by what it must
  do: moving shape A out along it by the depth plus 10 um separates the pair,
  by the depth less 10 um does not;
- near-degenerate pairs (within ``SEPARATED`` of touching): the distance
  within 1e-6 m of coal's (1e-5 m against a cylinder); the normal is not
  compared (it turns fast there);
- every pair: the witness points satisfy ``point_a - point_b = distance *
  normal`` to 1e-9 m (EPA's witnesses on a long, thin face, two support
  points a few um apart on a curved side, were up to 14 um off before), and
  near-degenerate ones lie on the shapes' surfaces.

Each check holds for every sample, not for one: the tests pass for every seed
of the generator (checked over 100), so their verdict does not hang on the
last bits of a processor's arithmetic. Coal is wrong in three kinds of
cylinder pair, which the checks work around and
:func:`test_known_hard_cylinder_cases_are_exact` pins with exact answers: a
point inside a cylinder, or on it, is as deep as below its side, also on a cap
(a witness on a cap seemed 2.8 mm inside); a sphere in a cylinder likewise
(up to 2.9 cm too deep near a cap, over 30 samples); and its GJK found 7 and
12 nm of clearance between a hull and a cylinder that overlap by 1.3 and
4.5 um (a point lies inside both).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import coal
import fcl
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial import ConvexHull

from cbp.collision import (
    CollisionSettings,
    CollisionWorld,
    EnvironmentObject,
    PrimitiveEnvironment,
    RobotGeometry,
)
from cbp.collision.convex_kernels import (
    CONVEX,
    FAILED,
    PlacedConvex,
    pack_shapes,
    pair_distance,
)
from cbp.collision.environment import signed_distance
from cbp.errors import ScenarioError
from cbp.state import RobotState
from cbp.testing import sample_configurations

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
#: Pairs nearer than this to touching [m] are near-degenerate (see above).
SEPARATED = 1e-4


@pytest.fixture(scope="module")
def geometry(robots) -> RobotGeometry:
    return RobotGeometry(robots["panda"])


def _shapes_a(geometry: RobotGeometry) -> list[coal.CollisionGeometry]:
    """The Panda's hulls and the primitives an attachment can be."""
    return [s.shape for s in geometry.shapes] + [
        coal.Box(0.08, 0.05, 0.03),
        coal.Sphere(0.04),
        coal.Capsule(0.03, 0.12),
        coal.Cylinder(0.04, 0.1),
    ]


def _shapes_b(geometry: RobotGeometry) -> list[coal.CollisionGeometry]:
    """Obstacles: box, sphere, cylinder, capsule and a mesh hull (link 6's)."""
    return [
        coal.Box(0.3, 0.1, 0.2),
        coal.Sphere(0.07),
        coal.Cylinder(0.05, 0.3),
        coal.Capsule(0.04, 0.2),
        geometry.shapes[6].shape,
    ]


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return np.asarray(pin.Quaternion(q[0], q[1], q[2], q[3]).matrix())


def _placed(packed, s, M) -> PlacedConvex:
    """Shape s of a packed table at placement M."""
    return PlacedConvex(
        packed.kind[s],
        packed.size[s],
        packed.radius[s],
        packed.vertices,
        packed.vertex_start[s],
        packed.vertex_start[s + 1],
        packed.neighbor_start,
        packed.neighbors,
        M.homogeneous,
    )


def _measure(packed_a, a, Ma, packed_b, b, Mb) -> tuple[int, np.ndarray]:
    """The kernel's (status, [distance, point on a, point on b, normal])."""
    out = np.empty(10)
    status = pair_distance(
        _placed(packed_a, a, Ma),
        _placed(packed_b, b, Mb),
        np.zeros(5),
        np.empty((16, 3)),
        out,
    )
    return status, out


def _fcl_geometry(shape: coal.CollisionGeometry) -> fcl.CollisionGeometry:
    if isinstance(shape, coal.Box):
        return fcl.Box(*(2.0 * np.asarray(shape.halfSide)))
    if isinstance(shape, coal.Sphere):
        return fcl.Sphere(shape.radius)
    if isinstance(shape, coal.Capsule):
        return fcl.Capsule(shape.radius, 2.0 * shape.halfLength)
    if isinstance(shape, coal.Cylinder):
        return fcl.Cylinder(shape.radius, 2.0 * shape.halfLength)
    assert isinstance(shape, coal.Convex)
    faces = [
        [3, *(int(shape.polygons(f)[k]) for k in range(3))]
        for f in range(shape.num_polygons)
    ]
    return fcl.Convex(
        np.asarray(shape.points(), dtype=float),
        len(faces),
        np.asarray(faces, dtype=np.int64).ravel(),
    )


class _Fcl:
    """python-fcl's signed distance of (a, b), with the normal from b toward a."""

    def __init__(self, shapes_a: list, shapes_b: list) -> None:
        self.a = [fcl.CollisionObject(_fcl_geometry(s)) for s in shapes_a]
        self.b = [fcl.CollisionObject(_fcl_geometry(s)) for s in shapes_b]
        self.request = fcl.DistanceRequest(
            enable_nearest_points=True, enable_signed_distance=True
        )

    def __call__(
        self, a: int, Ma: pin.SE3, b: int, Mb: pin.SE3
    ) -> tuple[float, np.ndarray]:
        oa, ob = self.a[a], self.b[b]
        oa.setTransform(fcl.Transform(Ma.rotation, Ma.translation))
        ob.setTransform(fcl.Transform(Mb.rotation, Mb.translation))
        result = fcl.DistanceResult()
        d = fcl.distance(oa, ob, self.request, result)
        pa, pb = result.nearest_points
        gap = np.asarray(pa) - np.asarray(pb)
        return float(d), gap / max(float(np.linalg.norm(gap)), 1e-300)


def _curved(*shapes: coal.CollisionGeometry) -> bool:
    """Whether EPA approximates a curved side (a cylinder's) in the pair."""
    return any(isinstance(s, coal.Cylinder) for s in shapes)


def _angle(u: np.ndarray, v: np.ndarray) -> float:
    return math.acos(min(1.0, max(-1.0, float(np.dot(u, v)))))


def _surface_distance(shape: coal.CollisionGeometry, local: np.ndarray) -> float:
    """How far a point (in the shape's frame) lies from the shape's surface [m].

    Closed forms for the primitives; for a hull, the depth below its nearest
    face inside, coal's distance outside. Coal's distance from a point inside
    a cylinder, or on its surface (on either side by a rounding), is the depth
    below its side, also for a point on a cap: 1.2 cm for a point on a cap.
    """
    if isinstance(shape, coal.Box):
        beyond = np.abs(local) - np.asarray(shape.halfSide)
        if beyond.max() <= 0.0:
            return float(-beyond.max())
        return float(np.linalg.norm(np.maximum(beyond, 0.0)))
    if isinstance(shape, coal.Sphere):
        return abs(float(np.linalg.norm(local)) - shape.radius)
    if isinstance(shape, coal.Capsule):
        on_axis = min(max(float(local[2]), -shape.halfLength), shape.halfLength)
        axis = float(np.linalg.norm(local - [0.0, 0.0, on_axis]))
        return abs(axis - shape.radius)
    if isinstance(shape, coal.Cylinder):
        side = math.hypot(local[0], local[1]) - shape.radius
        cap = abs(float(local[2])) - shape.halfLength
        if side <= 0.0 and cap <= 0.0:
            return -max(side, cap)
        return math.hypot(max(side, 0.0), max(cap, 0.0))
    planes = ConvexHull(np.asarray(shape.points(), dtype=float)).equations
    excess = float((planes[:, :3] @ local + planes[:, 3]).max())
    if excess <= 0.0:
        return -excess
    probe, request, result = (
        coal.Sphere(1e-12),
        coal.DistanceRequest(),
        coal.DistanceResult(),
    )
    return abs(
        coal.distance(
            shape, pin.SE3.Identity(), probe, pin.SE3(np.eye(3), local), request, result
        )
    )


def _on_surface(shape, M, point) -> float:
    """How far ``point`` lies from the shape at placement M's surface [m]."""
    return _surface_distance(shape, M.actInv(point))


def _coal_depth_is_right(*shapes: coal.CollisionGeometry) -> bool:
    """Whether coal's penetration depth holds for the pair.

    Not a sphere in a cylinder: coal takes its depth below the side, also
    where the sphere is nearer a cap (up to 2.9 cm too deep over 30 samples
    of the test below; fcl's is right there).
    """
    kinds = {type(shape) for shape in shapes}
    return kinds != {coal.Sphere, coal.Cylinder}


def _pairs(geometry, rng, count, spread):
    shapes_a, shapes_b = _shapes_a(geometry), _shapes_b(geometry)
    for _ in range(count):
        a = int(rng.integers(len(shapes_a)))
        b = int(rng.integers(len(shapes_b)))
        Ma = pin.SE3(_rotation(rng), rng.uniform(-spread, spread, 3))
        Mb = pin.SE3(_rotation(rng), rng.uniform(-0.05, 0.05, 3))
        yield a, Ma, b, Mb


def test_separated_pairs_match_coal_and_fcl(geometry, rng) -> None:
    """Separated pairs: coal's distance (1e-6 m) and normal (1e-3 rad); fcl's bound."""
    shapes_a, shapes_b = _shapes_a(geometry), _shapes_b(geometry)
    packed_a, packed_b = pack_shapes(shapes_a), pack_shapes(shapes_b)
    reference = _Fcl(shapes_a, shapes_b)
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    request.gjk_tolerance = 1e-10  # coal's default stops within 1e-6 (relative)
    kinds, checked = set(), 0
    for a, Ma, b, Mb in _pairs(geometry, rng, 1500, 0.3):
        d_coal, _, _, n_coal = signed_distance(
            shapes_b[b], Mb, shapes_a[a], Ma, request, result
        )
        if d_coal <= SEPARATED:
            continue
        status, out = _measure(packed_a, a, Ma, packed_b, b, Mb)
        assert status == 0
        d, n = out[0], out[7:]
        assert d == pytest.approx(d_coal, abs=1e-6)
        assert _angle(n, n_coal) < 1e-3, (a, b, d)
        d_fcl, _ = reference(a, Ma, b, Mb)
        assert d <= d_fcl + 1e-9, (a, b)
        np.testing.assert_allclose(out[1:4] - out[4:7], d * n, atol=1e-9)
        kinds.add((int(packed_a.kind[a]), int(packed_b.kind[b])))
        checked += 1
    assert checked > 800
    assert len(kinds) == 25  # every kind against every kind


def test_penetrating_pairs_match_coal_and_fcl_depths(geometry, rng) -> None:
    """Overlapping pairs: coal's and fcl's depth, and a normal that gets A out."""
    shapes_a, shapes_b = _shapes_a(geometry), _shapes_b(geometry)
    packed_a, packed_b = pack_shapes(shapes_a), pack_shapes(shapes_b)
    reference = _Fcl(shapes_a, shapes_b)
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    checked = 0
    for a, Ma, b, Mb in _pairs(geometry, rng, 1500, 0.1):
        d_coal = signed_distance(shapes_b[b], Mb, shapes_a[a], Ma, request, result)[0]
        if not -1.0 < d_coal < -SEPARATED:  # coal's EPA fails at times (-DBL_MAX)
            continue
        status, out = _measure(packed_a, a, Ma, packed_b, b, Mb)
        assert status == 0
        d, n = out[0], out[7:]
        tolerance = 1e-5 if _curved(shapes_a[a], shapes_b[b]) else 1e-6
        if _coal_depth_is_right(shapes_a[a], shapes_b[b]):
            assert d == pytest.approx(d_coal, abs=tolerance), (a, b)
        d_fcl, _ = reference(a, Ma, b, Mb)
        assert d == pytest.approx(d_fcl, abs=1e-5), (a, b)
        np.testing.assert_allclose(out[1:4] - out[4:7], d * n, atol=1e-9)
        for extra, separated in ((1e-5, True), (-1e-5, False)):
            moved = pin.SE3(Ma.rotation, Ma.translation + (-d + extra) * n)
            after = _measure(packed_a, a, moved, packed_b, b, Mb)[1][0]
            assert (after > 0.0) == separated, (a, b, d, extra, after)
        checked += 1
    assert checked > 300


def test_touching_and_near_pairs_agree_on_distance(geometry, rng) -> None:
    """Within 0.1 mm of touching: coal's distance, witnesses on the surfaces."""
    shapes_a, shapes_b = _shapes_a(geometry), _shapes_b(geometry)
    packed_a, packed_b = pack_shapes(shapes_a), pack_shapes(shapes_b)
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    request.gjk_tolerance = 1e-10
    checked = 0
    for a, Ma, b, Mb in _pairs(geometry, rng, 1000, 0.3):
        # Slide A toward B until coal finds them within 0.1 mm of touching.
        d_coal, _, _, n = signed_distance(
            shapes_b[b], Mb, shapes_a[a], Ma, request, result
        )
        if d_coal <= 0.0 or d_coal > 1.0:
            continue
        target = float(rng.uniform(-SEPARATED, SEPARATED))
        Ma = pin.SE3(Ma.rotation, Ma.translation - (d_coal - target) * n)
        d_coal = signed_distance(shapes_b[b], Mb, shapes_a[a], Ma, request, result)[0]
        if abs(d_coal) > SEPARATED:
            continue  # a corner moved past another face
        status, out = _measure(packed_a, a, Ma, packed_b, b, Mb)
        assert status == 0
        # Coal's GJK near a cylinder can miss a few um of overlap (see above).
        tolerance = 1e-5 if _curved(shapes_a[a], shapes_b[b]) else 1e-6
        assert out[0] == pytest.approx(d_coal, abs=tolerance), (a, b)
        np.testing.assert_allclose(out[1:4] - out[4:7], out[0] * out[7:], atol=1e-9)
        # EPA's witnesses of an overlap interpolate support points: on a hull
        # they may lie inside by a small weight times how deep the chord
        # between two of its vertices runs (0.7 um at most in 92,000 pairs).
        on_surface = 1e-6 if out[0] >= 0.0 else 2e-6
        assert _on_surface(shapes_a[a], Ma, out[1:4]) < on_surface
        assert _on_surface(shapes_b[b], Mb, out[4:7]) < on_surface
        checked += 1
    assert checked > 600


def _hard_case(case: str, gap: float) -> tuple[list, list, float, np.ndarray]:
    """Shapes A and B placed ``gap`` apart along world z, A above, where coal errs.

    ``rim_on_cap``: a tilted cylinder's rim over another's cap (a witness on the
    cap); ``edge_on_side``: a box's edge along a lying cylinder's side;
    ``sphere_at_cap``: a sphere in a cylinder, poking ``gap`` out of its cap.
    Returns the shapes, their placements, the exact signed distance and the
    normal from B toward A.
    """
    up = np.array([0.0, 0.0, 1.0])
    if case == "rim_on_cap":
        a, b = coal.Cylinder(0.05, 0.3), coal.Cylinder(0.04, 0.1)
        R = pin.AngleAxis(0.8, np.array([1.0, 0.3, 0.0]) / math.hypot(1.0, 0.3))
        R = R.matrix()
        local = R.T @ -up  # the rim point lowest along z
        across = math.hypot(local[0], local[1])
        lowest = R @ [0.05 * local[0] / across, 0.05 * local[1] / across, -0.15]
        Ma = pin.SE3(R, np.array([0.01, -0.005, gap]) - lowest)
        Mb = pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.05]))  # its cap at z = 0
        return [a, b], [Ma, Mb], gap, up
    if case == "edge_on_side":
        a, b = coal.Box(0.1, 0.1, 0.1), coal.Cylinder(0.05, 0.4)
        turned = pin.AngleAxis(math.pi / 4, np.array([0.0, 1.0, 0.0])).matrix()
        lying = pin.AngleAxis(math.pi / 2, np.array([1.0, 0.0, 0.0])).matrix()
        Ma = pin.SE3(turned, np.array([0.0, 0.0, 0.05 + 0.05 * math.sqrt(2) + gap]))
        return [a, b], [Ma, pin.SE3(lying, np.zeros(3))], gap, up
    assert case == "sphere_at_cap"
    a, b = coal.Sphere(0.02), coal.Cylinder(0.05, 0.1)
    Ma = pin.SE3(np.eye(3), np.array([0.02, 0.0, 0.05 - 0.02 + gap]))
    # Out through the cap: the sphere's depth below it and its diameter.
    return [a, b], [Ma, pin.SE3.Identity()], gap - 0.04, up


@pytest.mark.parametrize("gap", [-3e-5, -1e-6, 0.0, 1e-6, 3e-5])
@pytest.mark.parametrize("case", ["rim_on_cap", "edge_on_side", "sphere_at_cap"])
def test_known_hard_cylinder_cases_are_exact(case, gap) -> None:
    """Where coal errs near a cylinder: the exact distance, witnesses on the surfaces."""
    (a, b), (Ma, Mb), expected, normal = _hard_case(case, gap)
    packed_a, packed_b = pack_shapes([a]), pack_shapes([b])
    status, out = _measure(packed_a, 0, Ma, packed_b, 0, Mb)
    assert status == 0
    assert out[0] == pytest.approx(expected, abs=1e-8)
    if gap != 0.0:  # touching, the normal turns fast (the module's docstring)
        np.testing.assert_allclose(out[7:], normal, atol=1e-3)
    np.testing.assert_allclose(out[1:4] - out[4:7], out[0] * out[7:], atol=1e-9)
    assert _on_surface(a, Ma, out[1:4]) < 1e-8
    assert _on_surface(b, Mb, out[4:7]) < 1e-8


def test_a_sphere_inside_a_cylinder_is_as_deep_as_the_closed_form(rng) -> None:
    """A sphere anywhere inside a cylinder: its depth within 1 mm, most to 10 um.

    EPA approximates the side by faces between rim points, and its support
    points crowd there; where one more would break its polytope (round-off on
    faces a few um wide) it stops at the nearest face. It used to take the
    step: 1.6 % of these depths came out up to 22 cm short.
    """
    sphere, cylinder = (
        pack_shapes([coal.Sphere(0.04)]),
        pack_shapes([coal.Cylinder(0.05, 0.3)]),
    )
    errors = []
    for _ in range(500):
        radial, angle = rng.uniform(0.0, 0.045), rng.uniform(0.0, 2.0 * math.pi)
        z = rng.uniform(-0.14, 0.14)
        Mc = pin.SE3(_rotation(rng), rng.uniform(-0.05, 0.05, 3))
        centre = [radial * math.cos(angle), radial * math.sin(angle), z]
        Ms = pin.SE3(np.eye(3), Mc.act(np.array(centre)))
        status, out = _measure(sphere, 0, Ms, cylinder, 0, Mc)
        assert status == 0
        exact = -(0.04 + min(0.05 - radial, 0.15 - abs(z)))
        errors.append(abs(out[0] - exact))
    assert max(errors) < 1e-3
    assert np.mean(np.array(errors) < 1e-5) > 0.95


def test_faces_in_contact_give_the_face_normal() -> None:
    """Two boxes face to face: distance exactly 0 or the gap, normal along the face."""
    packed = pack_shapes([coal.Box(0.2, 0.2, 0.2), coal.Box(1.0, 1.0, 0.1)])
    below = pin.SE3(np.eye(3), np.array([0.3, -0.2, 0.0]))
    for gap in (0.0, 1e-7, 0.01, -0.02):
        above = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.05 + 0.1 + gap]))
        status, out = _measure(packed, 0, above, packed, 1, below)
        assert status == 0
        assert out[0] == pytest.approx(gap, abs=1e-12)
        np.testing.assert_allclose(out[7:], [0.0, 0.0, 1.0], atol=1e-8)


def test_hulls_are_packed_with_their_edges(geometry) -> None:
    """Every hull vertex has neighbours, and climbing them finds the farthest."""
    packed = pack_shapes([s.shape for s in geometry.shapes])
    assert (packed.kind == CONVEX).all()
    counts = np.diff(packed.neighbor_start)
    assert counts.min() >= 3
    assert packed.neighbors.min() >= 0
    assert packed.neighbors.max() < len(packed.vertices)
    assert FAILED != 0


def _worlds(scenario):
    world = scenario.world_for_run()
    coal_world = CollisionWorld(
        world.geometry,
        world.environment,
        dataclasses.replace(world.settings, narrow_phase="coal"),
    )
    return world, coal_world


def _compare_sets(compiled, reference, margin) -> int:
    """Same contacts (shape pairs), distances within 1e-6 m, normals 1e-3 rad."""
    key_c = sorted(
        zip(compiled.shape.tolist(), compiled.other_shape.tolist(), strict=True)
    )
    key_r = sorted(
        zip(reference.shape.tolist(), reference.other_shape.tolist(), strict=True)
    )
    if key_c != key_r:  # only a pair at the margin itself may differ
        near_margin = np.abs(reference.distance - margin) < 1e-6
        assert near_margin.any(), (key_c, key_r)
        return 0
    # One shape may touch several objects: ordered by distance within a pair.
    oc = np.lexsort((compiled.distance, compiled.other_shape, compiled.shape))
    orf = np.lexsort((reference.distance, reference.other_shape, reference.shape))
    np.testing.assert_allclose(
        compiled.distance[oc], reference.distance[orf], rtol=0, atol=1e-6
    )
    for k, r in zip(oc, orf, strict=True):
        if reference.distance[r] > SEPARATED - 0.01:  # separated (padded by 1 cm)
            assert _angle(compiled.normal[k], reference.normal[r]) < 1e-3
    return len(oc)


@pytest.mark.parametrize("scene", ["cat_boards.yaml", "cat_shelf_retreat.yaml"])
def test_world_contacts_match_the_coal_path(scene, robots, rng) -> None:
    """CollisionWorld's compiled query gives the coal path's contacts."""
    from cbp.scenario import load_scenario

    scenario = load_scenario(SCENARIOS / scene)
    world, coal_world = _worlds(scenario)
    state = RobotState(scenario.robot)
    found = 0
    configurations = [scenario.q0 + rng.normal(scale=0.2, size=len(scenario.q0))]
    configurations += list(sample_configurations(scenario.robot, rng, n=40))
    for q in configurations:
        state.update(q)
        compiled, reference = world.query(state), coal_world.query(state)
        margin = world.settings.activation_distance
        found += _compare_sets(compiled, reference, margin)
        # Both parts, as the contact constraints take them.
        assert len(compiled.environment_part()) == len(reference.environment_part())
        assert len(compiled.self_part()) == len(reference.self_part())
    assert found > 20


def test_meshes_and_wanted_contacts_follow_the_coal_path(
    geometry, robots, tmp_path
) -> None:
    """A non-convex mesh goes to coal; allowed contacts are left out either way."""
    import trimesh

    path = tmp_path / "ring.stl"
    trimesh.creation.annulus(r_min=0.05, r_max=0.15, height=0.04).export(path)
    robot = robots["panda"]
    state = RobotState(robot, robot.home())
    hand = next(s for s in geometry.shapes if s.link == "panda_hand")
    below = hand.world_placement(state).translation - [0.0, 0.0, 0.12]
    ring = EnvironmentObject.mesh("ring", path, np.ones(3), pin.SE3(np.eye(3), below))
    assert isinstance(ring.shape, coal.BVHModelBase)
    table = EnvironmentObject.primitive(
        "table", "box", (1.0, 1.0, 0.05), pin.SE3(np.eye(3), below - [0, 0, 0.1])
    )
    table = dataclasses.replace(table, allow_contact=frozenset({"panda_hand"}))
    env = PrimitiveEnvironment([ring, table])
    settings = CollisionSettings(activation_distance=0.3)
    compiled = CollisionWorld(geometry, env, settings).query(state)
    reference = CollisionWorld(
        geometry, env, dataclasses.replace(settings, narrow_phase="coal")
    ).query(state)
    assert _compare_sets(compiled, reference, 0.3) > 0
    hand_index = geometry.shapes.index(hand)
    obstacles = compiled.environment_part()
    assert hand_index in obstacles.shape.tolist()  # the ring, through coal
    assert len(obstacles) == len(reference.environment_part())


def test_narrow_phase_setting_is_checked() -> None:
    """An unknown collision.narrow_phase is a located error."""
    from cbp.scenario import load_scenario

    with pytest.raises(ScenarioError, match=r"collision\.narrow_phase: got 'fast'"):
        load_scenario(
            SCENARIOS / "cat_boards.yaml", overrides={"collision.narrow_phase": "fast"}
        )


def test_cores_that_coincide_go_to_coal() -> None:
    """A sphere centred on a capsule's axis: EPA cannot start; coal measures it."""
    from cbp.collision.geometry import LinkShape, PlacedShapes, ShapePlacements

    capsule = LinkShape.probe("capsule", coal.Capsule(0.05, 0.2))
    packed_a = pack_shapes([capsule.shape])
    packed_b = pack_shapes([coal.Sphere(0.03)])
    on_axis = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.04]))
    status, _ = _measure(packed_a, 0, pin.SE3.Identity(), packed_b, 0, on_axis)
    assert status == FAILED
    ball = EnvironmentObject.primitive("ball", "sphere", (0.03,), on_axis)
    env = PrimitiveEnvironment([ball])
    placed = PlacedShapes(
        [capsule],
        ShapePlacements([pin.SE3.Identity()]),
        np.array([capsule.centre]),
        np.array([capsule.radius]),
        np.array([0.5 * (capsule.upper - capsule.lower)]),
    )
    compiled = env.query(placed, 0.05, 3, "compiled")
    reference = env.query(placed, 0.05, 3, "coal")
    assert len(compiled) == len(reference) == 1
    assert compiled.distance[0] == pytest.approx(-0.08, abs=1e-6)
    assert compiled.distance[0] == pytest.approx(reference.distance[0], abs=1e-9)
