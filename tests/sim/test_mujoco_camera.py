"""MuJoCo's depth cameras (ray cast, OpenGL): known surfaces within a cell, PyBullet's pixels."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

import cbp.sim.mujoco  # noqa: F401  (OpenGL through EGL before mujoco loads)
from cbp.errors import ConfigError
from cbp.perception.spec import CameraSpec, DepthNoise, PerceptionSpec
from cbp.scenario import ObjectSpec, load_scenario
from cbp.scenario.scene import SimulationSettings
from cbp.sim.camera import DepthCamera
from cbp.sim.raycast import RayCaster
from cbp.sim.scene import PybulletScene
from cbp.spatial import Pose
from cbp.state import RobotState
from tests.sim.test_raycast import SCENARIOS
from tests.sim.test_raycast import _cameras as _raycast_cameras

mujoco = pytest.importorskip("mujoco")

from cbp.sim.mujoco.camera import MujocoDepthCamera, Renderers  # noqa: E402
from cbp.sim.mujoco.physics import MujocoPhysics  # noqa: E402
from cbp.sim.mujoco.raycast import MujocoRayCaster  # noqa: E402

EXACT = DepthNoise(enabled=False)
CELL = PerceptionSpec().cell_size

CENTIMETRE = 0.01
#: MuJoCo's and the ray cast's frames of the boards agree within a centimetre
#: on at least this fraction of all pixels, and of each image's (both see
#: nothing, or both a surface that near). Measured (18 images at 128 x 96):
#: MuJoCo's ray cast, every pixel within 1 mm; its OpenGL renderer, 99.998 %
#: of all pixels within 1 mm, at least 99.99 % per image.
AGREEING, AGREEING_PER_IMAGE = 0.999, 0.998

#: The scene: a floor plane at z = 0, a box, a sphere, a cylinder and a cube
#: given as a mesh, each (type, position, rotation, size as MuJoCo takes it).
BOX = (np.array([1.0, 0.0, 0.15]), pin.rpy.rpyToMatrix(0.0, 0.0, 0.3), (0.1, 0.2, 0.15))
SPHERE = (np.array([0.8, -0.45, 0.12]), 0.12)
CYLINDER = (np.array([0.85, 0.45, 0.2]), pin.rpy.rpyToMatrix(0.4, 0.2, 0.0), 0.07, 0.2)
CUBE = (np.array([0.6, 0.0, 0.3]), pin.rpy.rpyToMatrix(0.3, 0.5, 0.2), 0.05)


def _quaternion(rotation: np.ndarray) -> list[float]:
    q = pin.Quaternion(rotation)
    return [q.w, q.x, q.y, q.z]


def _scene() -> tuple[Any, Any]:
    """The model and data of the scene, built with MuJoCo's spec."""
    spec = mujoco.MjSpec()
    world = spec.worldbody
    world.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 1.0])
    position, rotation, half = BOX
    world.add_geom(
        type=mujoco.mjtGeom.mjGEOM_BOX, pos=position, quat=_quaternion(rotation),
        size=half,
    )  # fmt: skip
    world.add_geom(
        type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=SPHERE[0], size=[SPHERE[1], 0, 0]
    )
    position, rotation, radius, half_length = CYLINDER
    world.add_geom(
        type=mujoco.mjtGeom.mjGEOM_CYLINDER, pos=position,
        quat=_quaternion(rotation), size=[radius, half_length, 0.0],
    )  # fmt: skip
    position, rotation, half = CUBE
    corners = np.array([[(i >> k & 1) * 2 - 1 for k in range(3)] for i in range(8)])
    faces = [
        [0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
        [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5],
    ]  # fmt: skip
    spec.add_mesh(
        name="cube",
        uservert=(half * corners).ravel().tolist(),
        userface=np.ravel(faces).tolist(),
    )
    world.add_geom(
        type=mujoco.mjtGeom.mjGEOM_MESH, meshname="cube", pos=position,
        quat=_quaternion(rotation),
    )  # fmt: skip
    model = spec.compile()
    return model, mujoco.MjData(model)


def _box_distance(
    points: np.ndarray, position: np.ndarray, rotation: np.ndarray, half: object
) -> np.ndarray:
    """Distance of points (n, 3) to a box's surface [m]."""
    local = np.abs((points - position).dot(rotation)) - np.asarray(half, dtype=float)
    outside = np.linalg.norm(np.maximum(local, 0.0), axis=1)
    return np.where(np.any(local > 0, axis=1), outside, -np.max(local, axis=1))


def _surface_distance(points: np.ndarray) -> np.ndarray:
    """Distance of world points (n, 3) to the scene's nearest surface [m]."""
    floor = np.abs(points[:, 2])
    box = _box_distance(points, *BOX)
    cube = _box_distance(points, CUBE[0], CUBE[1], (CUBE[2],) * 3)
    ball = np.abs(np.linalg.norm(points - SPHERE[0], axis=1) - SPHERE[1])
    position, rotation, radius, half_length = CYLINDER
    local = (points - position).dot(rotation)
    radial = np.linalg.norm(local[:, :2], axis=1) - radius
    axial = np.abs(local[:, 2]) - half_length
    outside = np.hypot(np.maximum(radial, 0.0), np.maximum(axial, 0.0))
    can = np.where((radial > 0) | (axial > 0), outside, -np.maximum(radial, axial))
    return np.asarray(np.min([floor, box, cube, ball, can], axis=0))


RENDERERS = pytest.mark.parametrize("renderer", ["raycast", "opengl"])


def _camera(model: Any, data: Any, renderer: str, **kwargs: Any) -> MujocoDepthCamera:
    spec = CameraSpec(
        name="c", position=(-0.2, 0.0, 0.7), target=(0.8, 0.0, 0.1), width=160,
        height=120, fov_deg=60.0, far=2.5, noise=EXACT, renderer=renderer,
    )  # fmt: skip
    return MujocoDepthCamera(model, data, replace(spec, **kwargs))


@RENDERERS
def test_a_box_face_at_a_known_distance_is_seen_there_within_a_cell(
    renderer: str,
) -> None:
    """The conformance check: a box face 1.2 m ahead reads 1.2 m (within a cell)."""
    model, data = _scene()
    camera = _camera(
        model, data, renderer, position=(-0.2, 0.0, 0.15), target=(1.0, 0.0, 0.15)
    )
    # The box's nearest face, turned 0.3 rad: its centre lies 1.2 - 0.1 / cos(0.3)
    # ahead; the pixel on the axis sees it there.
    ranges = camera.capture().ranges()
    h, w = ranges.shape
    expected = 1.2 - BOX[2][0] / np.cos(0.3)
    assert abs(ranges[h // 2, w // 2] - expected) < CELL
    # ... and every pixel's point lies on a surface of the scene.
    points, hit = camera.capture().points()
    assert hit.mean() > 0.5
    assert np.max(_surface_distance(points[hit])) < CELL


@RENDERERS
def test_every_pixel_lies_on_the_surface_it_sees(renderer: str) -> None:
    """Plane, box, sphere, cylinder and mesh: within 0.5 mm (facets), most exact."""
    model, data = _scene()
    points, hit = _camera(model, data, renderer).capture().points()
    distance = _surface_distance(points[hit])
    assert hit.mean() > 0.7  # the floor up to 2.5 m, and the objects
    assert np.max(distance) < 5e-4  # spheres and cylinders are drawn as facets
    assert np.median(distance) < 1e-5  # pixels sample where the frame says


@RENDERERS
def test_nearer_than_the_clipping_plane_is_cut_and_beyond_far_unseen(
    renderer: str,
) -> None:
    """The far plane bounds what is seen; the minimum range gives no reading."""
    model, data = _scene()
    far = _camera(model, data, renderer, far=1.0).capture()
    assert np.all(np.isinf(far.ranges()) | (far.ranges() < 1.0))
    assert np.isinf(far.ranges()).mean() > 0.1  # the floor beyond 1 m
    near = _camera(model, data, renderer, near=0.8).capture()
    ranges = near.ranges()
    assert np.isnan(ranges).mean() > 0.1  # the floor nearer than 0.8 m
    assert np.all(np.isnan(ranges) | (ranges >= 0.8))


def test_cameras_of_one_size_share_one_renderer() -> None:
    """One OpenGL context per image size, whatever the number of cameras."""
    model, data = _scene()
    renderers = Renderers(model)
    specs = [
        CameraSpec(name=f"c{i}", position=p, target=(0.8, 0.0, 0.1), width=w,
                   height=h, noise=EXACT, renderer="opengl")
        for i, (p, w, h) in enumerate([
            ((-0.2, 0.0, 0.7), 64, 48), ((0.8, -1.0, 0.6), 64, 48),
            ((0.8, 1.0, 0.6), 32, 24),
        ])
    ]  # fmt: skip
    cameras = [MujocoDepthCamera(model, data, s, None, renderers) for s in specs]
    frames = [c.capture() for c in cameras]
    assert [f.depth.shape for f in frames] == [(48, 64), (48, 64), (24, 32)]
    assert renderers.count == 2
    for frame in frames:  # each from its own place
        points, hit = frame.points()
        assert hit.mean() > 0.5
        assert np.max(_surface_distance(points[hit])) < 1e-3
    renderers.close()


def _set_configuration(physics: Any, robot: Any, q: np.ndarray) -> None:
    """Put MuJoCo's robot at ``q`` (its joints by name)."""
    model = robot.model
    names = [model.names[j] for j in range(1, model.njoints) if model.joints[j].nv == 1]
    for name, value in zip(names, q, strict=True):
        physics.data.joint(name).qpos[0] = value


def _boards() -> tuple[Any, Any, list[Any]]:
    """The boards scenario, MuJoCo's physics of it, and three configurations."""
    scenario = load_scenario(SCENARIOS / "cat_boards.yaml")
    robot = scenario.robot
    physics = MujocoPhysics(
        robot, list(scenario.spec.world.objects), scenario.q0, SimulationSettings()
    )
    rng = np.random.default_rng(3)
    lower, upper = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    configurations = [scenario.q0] + [
        np.clip(scenario.q0 + 0.3 * rng.uniform(-1.0, 1.0, robot.nq), lower, upper)
        for _ in range(2)
    ]
    return scenario, physics, configurations


@RENDERERS
def test_mujoco_and_pybullet_frames_of_the_boards_agree_within_a_centimetre(
    renderer: str,
) -> None:
    """The Panda's meshes over the boards, five fixed cameras and the hand's.

    Compared as the ray cast is with the tiny renderer
    (``tests/sim/test_raycast.py``), against the ray cast: the rest lie on
    silhouette edges.
    """
    scenario, physics, configurations = _boards()
    robot = scenario.robot
    renderers = Renderers(physics.model)
    agree = []
    with PybulletScene(robot, list(scenario.spec.world.objects)) as sim:
        caster = RayCaster(sim.client)
        state = RobotState(robot)
        for q in configurations:
            sim.set_configuration(q)
            _set_configuration(physics, robot, q)
            state.update(q)
            for spec in _raycast_cameras():
                at = state if spec.parent else None
                ours = replace(spec, renderer=renderer)
                cast = DepthCamera(sim.client, spec, robot, caster).capture(at)
                mj = MujocoDepthCamera(
                    physics.model, physics.data, ours, robot, renderers
                ).capture(at)
                a, b = cast.ranges(), mj.ranges()
                with np.errstate(invalid="ignore"):
                    same = (np.isinf(a) & np.isinf(b)) | (np.isnan(a) & np.isnan(b))
                    agree.append(same | (np.abs(a - b) <= CENTIMETRE))
    renderers.close()
    assert np.mean(agree) >= AGREEING
    assert min(np.mean(a) for a in agree) >= AGREEING_PER_IMAGE


@RENDERERS
def test_a_camera_on_the_hand_moves_with_it(renderer: str) -> None:
    """The hand's camera sits at its offset from the hand, wherever the arm is.

    Its frames see the board below from where the hand is: the points it
    sees of the table's top stay on it as the hand moves.
    """
    scenario, physics, configurations = _boards()
    robot = scenario.robot
    spec = replace(next(c for c in _raycast_cameras() if c.parent), renderer=renderer)
    camera = MujocoDepthCamera(physics.model, physics.data, spec, robot)
    hand = robot.frame_id("panda_hand")
    state = RobotState(robot)
    seen = []
    for q in configurations:
        _set_configuration(physics, robot, q)
        state.update(q)
        frame = camera.capture(state)
        expected = state.data.oMf[hand] * spec.offset.to_se3()
        assert np.allclose(frame.position, expected.translation, atol=1e-6)
        assert np.allclose(camera.optical_pose(state).rotation, expected.rotation)
        seen.append(frame.position)
        points, hit = frame.points()
        table = np.abs(points[hit][:, 2]) < 2e-3  # the table's top, z = 0
        assert np.count_nonzero(table) > 100
        assert np.all(np.abs(points[hit][table][:, 0] - 0.55) <= 0.3 + 1e-3)
    assert np.linalg.norm(seen[1] - seen[0]) > 0.05  # the hand moved
    camera.close()


def test_a_renderer_of_the_other_engine_is_refused_by_name() -> None:
    """``tiny`` is PyBullet's, ``opengl`` MuJoCo's: each engine says so."""
    model, data = _scene()
    with pytest.raises(ConfigError, match="renderer 'tiny' is PyBullet's"):
        _camera(model, data, "tiny")
    robot = load_scenario(SCENARIOS / "cat_boards.yaml").robot
    spec = CameraSpec(position=(1.0, 0.0, 1.0), target=(0, 0, 0), renderer="opengl")
    refused = pytest.raises(ConfigError, match="renderer 'opengl' is MuJoCo's")
    with PybulletScene(robot, []) as sim, refused:
        DepthCamera(sim.client, spec)


def test_a_geom_the_ray_cast_cannot_draw_is_named() -> None:
    """An ellipsoid is refused with its name and body."""
    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name="egg_holder")
    body.add_geom(
        name="egg", type=mujoco.mjtGeom.mjGEOM_ELLIPSOID, size=[0.1, 0.2, 0.3]
    )
    model = spec.compile()
    with pytest.raises(
        ValueError, match=r"geom egg \(body 'egg_holder'\): type mjGEOM_ELLIPSOID"
    ):
        MujocoRayCaster(model, mujoco.MjData(model))


@RENDERERS
def test_an_object_that_appears_is_seen_once_it_is_there(renderer: str) -> None:
    """A box appearing at 0.5 s: not in the frames before, in those after."""
    scenario = load_scenario(SCENARIOS / "cat_boards.yaml")
    wall = ObjectSpec(
        name="wall", shape="box", size=(0.4, 0.06, 0.5),
        pose=Pose(position=(0.5, 0.2, 0.25)), appear_at=0.5,
    )  # fmt: skip
    physics = MujocoPhysics(
        scenario.robot, [wall], scenario.q0, SimulationSettings(rate_hz=100.0)
    )
    spec = CameraSpec(
        name="c", position=(0.5, 1.2, 0.3), target=(0.5, 0.0, 0.25), width=64,
        height=48, noise=EXACT, renderer=renderer,
    )  # fmt: skip
    camera = MujocoDepthCamera(physics.model, physics.data, spec)
    centre, half = np.array(wall.pose.position), (0.2, 0.03, 0.25)

    def on_wall() -> int:
        points, hit = camera.capture().points()
        distance = _box_distance(points[hit], centre, np.eye(3), half)
        return int(np.count_nonzero(np.abs(distance) < 1e-3))

    assert on_wall() == 0
    for k in range(60):  # 0.6 s
        physics.step(0.01 * (k + 1))
    assert on_wall() > 200
    camera.close()
