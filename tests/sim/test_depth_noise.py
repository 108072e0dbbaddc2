"""The depth noise model: range-dependent noise, lost edges, dropout, seeds, off."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cbp.collision import RobotGeometry
from cbp.errors import ScenarioError
from cbp.perception.frame import DepthFrame
from cbp.perception.occupancy import OccupancyGrid
from cbp.perception.spec import CameraSpec, DepthNoise, PerceptionSpec
from cbp.scenario import ObjectSpec, load_scenario
from cbp.sim.bullet import pb
from cbp.sim.camera import DepthCamera
from cbp.sim.depth_noise import NoisyDepth
from cbp.sim.scene import PybulletScene
from cbp.spatial import Pose
from cbp.state import RobotState

NEAR, FAR = 0.0025, 3.0
H, W = 120, 160
PROJECTION = np.array(pb.computeProjectionMatrixFOV(60.0, W / H, NEAR, FAR))
VIEW = np.array(pb.computeViewMatrix([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0, 0, 1]))


def _frame(depth: np.ndarray) -> DepthFrame:
    """A frame of metric depths (inf: background), as a depth buffer."""
    buffer = np.where(np.isinf(depth), 1.0, FAR / (FAR - NEAR) * (1 - NEAR / depth))
    return DepthFrame(
        buffer, VIEW.reshape(4, 4).T, PROJECTION.reshape(4, 4).T, NEAR, FAR, "c"
    )


def _apply(noise: DepthNoise, depth: np.ndarray, camera: str = "c") -> DepthFrame:
    frame = _frame(depth)
    far_plane = frame.buffer_limits[1]
    noisy = NoisyDepth(noise, camera).apply(frame.depth, NEAR, FAR, far_plane)
    return replace(frame, depth=noisy)


ONLY_NOISE = DepthNoise(edge_jump=0.0, dropout=0.0)


@pytest.mark.parametrize("z", [0.5, 1.0, 1.5, 2.5])
def test_the_noise_s_spread_is_sigma_of_the_range(z: float) -> None:
    """Readings of a flat wall at z scatter with sigma(z) = a + b (z - z0)^2."""
    noisy = _apply(ONLY_NOISE, np.full((H, W), z)).ranges()
    expected = 0.0012 + 0.0019 * (z - 0.4) ** 2
    assert ONLY_NOISE.sigma(z) == pytest.approx(expected)
    assert np.isfinite(noisy).all()
    assert np.mean(noisy) == pytest.approx(z, abs=4 * expected / np.sqrt(H * W))
    assert np.std(noisy) == pytest.approx(expected, rel=0.03)


def test_sigma_grows_with_the_range_past_z0() -> None:
    """Beyond z0 the noise only grows; switched off it is zero."""
    z = np.linspace(0.4, 3.0, 50)
    assert np.all(np.diff(ONLY_NOISE.sigma(z)) > 0)
    assert ONLY_NOISE.sigma(0.4) == pytest.approx(0.0012)
    assert not np.any(replace(ONLY_NOISE, enabled=False).sigma(z))


def test_the_far_side_of_a_depth_edge_gives_no_reading() -> None:
    """A jump beyond edge_jump loses the far pixel beside it; a smaller one none."""
    noise = DepthNoise(sigma_0=0.0, sigma_growth=0.0, dropout=0.0, edge_jump=0.03)
    depth = np.full((H, W), 1.5)
    depth[:, :60] = 1.0  # a near surface on the left
    depth[:, 100:] = 1.52  # a small step on the right
    depth[:10, :] = np.inf  # background at the top
    frame = _apply(noise, depth)
    valid = frame.valid()
    assert not valid[10:, 60].any()  # far side of the 0.5 m edge
    assert valid[10:, 59].all()  # its near side
    assert valid[10:, 61].all()  # beyond the edge
    assert valid[10:, 99:101].all()  # a 2 cm step is kept
    assert not valid[9, :].any()  # background beside the surface's top row
    assert np.flatnonzero(~valid[10]).tolist() == [60]  # the surface: near side
    assert valid[:9].all()  # background elsewhere stays background
    assert np.count_nonzero(~valid) == (H - 10) + W
    np.testing.assert_allclose(frame.ranges()[valid], depth[valid], rtol=1e-9)


@pytest.mark.parametrize("fraction", [0.0, 0.002, 0.05])
def test_the_dropout_fraction_is_as_set(fraction: float) -> None:
    """A dropout fraction p loses p of the pixels, at random."""
    noise = DepthNoise(sigma_0=0.0, sigma_growth=0.0, edge_jump=0.0, dropout=fraction)
    lost = np.mean(~_apply(noise, np.full((480, 640), 1.0)).valid())
    assert lost == pytest.approx(fraction, abs=4 * np.sqrt(fraction / (480 * 640)))


def test_a_camera_s_frames_repeat_with_its_seed() -> None:
    """Same seed and camera: the same frames; another seed or camera: others."""
    depth = np.full((H, W), 1.2)
    depth[:, :50] = 0.8

    def frames(noise: DepthNoise, camera: str) -> list[np.ndarray]:
        frame = _frame(depth)
        model = NoisyDepth(noise, camera)
        return [model.apply(frame.depth, NEAR, FAR, 1 - 1e-6) for _ in range(3)]

    first = frames(DepthNoise(), "head")
    np.testing.assert_array_equal(first, frames(DepthNoise(), "head"))
    assert not np.array_equal(first[0], first[1])  # frame to frame
    valid = np.isfinite(first[0])
    for other in (frames(DepthNoise(seed=1), "head"), frames(DepthNoise(), "side")):
        assert not np.array_equal(first[0][valid], other[0][valid])


@pytest.fixture
def scene(robots):
    robot = robots["panda"]
    box = ObjectSpec(
        name="box",
        shape="box",
        size=(0.2, 0.2, 0.2),
        pose=Pose(position=(0.6, 0.3, 0.1)),
    )
    with PybulletScene(robot, [box]) as scene:
        scene.set_configuration(robot.home())
        yield scene


CAMERA = CameraSpec(name="c", position=(1.6, 0.0, 0.9), target=(0.4, 0.0, 0.3))


def test_switched_off_frames_are_exactly_as_rendered(scene) -> None:
    """With ``noise: {enabled: false}`` a frame is PyBullet's depth buffer as is."""
    exact = replace(CAMERA, noise=DepthNoise(enabled=False), renderer="tiny")
    camera = DepthCamera(scene.client, exact)
    frame = camera.capture()
    _, _, _, depth, _ = pb.getCameraImage(
        CAMERA.width,
        CAMERA.height,
        viewMatrix=camera.view.T.reshape(-1).tolist(),
        projectionMatrix=camera.projection.T.reshape(-1).tolist(),
        renderer=pb.ER_TINY_RENDERER,
        flags=pb.ER_NO_SEGMENTATION_MASK,
        physicsClientId=scene.client,
    )
    rendered = np.asarray(depth, dtype=float).reshape(CAMERA.height, CAMERA.width)
    np.testing.assert_array_equal(frame.depth, rendered)
    noisy = DepthCamera(scene.client, replace(CAMERA, renderer="tiny")).capture()
    assert CAMERA.noise.enabled
    assert not np.array_equal(noisy.depth, rendered)
    assert 0.9 < noisy.valid().mean() < 1.0


def test_the_robot_filter_grows_with_the_camera_s_noise(scene, robots) -> None:
    """With noise on, the arm's readings are dropped, however they scatter.

    From about 1.4 m the noise (sigma 3 mm) scatters readings of the arm past
    the bare 5 mm margin: they would be mapped as obstacle cells on the arm;
    with the margin grown by 3 sigma none are.
    """
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    state = RobotState(robot, robot.home())
    spec = PerceptionSpec(
        source="depth_camera",
        camera=CAMERA,
        bounds=((-0.3, -0.6, 0.0), (1.0, 0.6, 1.2)),
    )
    camera = DepthCamera(scene.client, CAMERA)  # the grid takes its noise by name

    def cells_on_the_arm(map_sigmas: float) -> int:
        noise = replace(CAMERA.noise, map_sigmas=map_sigmas)
        grid = OccupancyGrid(
            replace(spec, camera=replace(CAMERA, noise=noise)), geometry
        )
        for _ in range(5):
            grid.integrate(camera.capture(), state)
        centres = grid.centres()
        # Cells within the padded arm: none without noise (checked below).
        return int(np.count_nonzero(geometry.contains(state, centres, margin=0.0)))

    assert cells_on_the_arm(0.0) > 50
    assert cells_on_the_arm(3.0) == 0
    exact = replace(CAMERA, noise=DepthNoise(enabled=False))
    grid = OccupancyGrid(replace(spec, camera=exact), geometry)
    grid.integrate(DepthCamera(scene.client, exact).capture(), state)
    assert grid.robot_points_removed > 1000  # the camera sees the arm
    assert not geometry.contains(state, grid.centres(), margin=0.0).any()


def test_a_static_scene_with_noise_hides_next_to_nothing(robots) -> None:
    """The hidden-space gap grows with the noise: a still scene hides (almost) nothing.

    A camera 2.5 m from a table and a box (sigma about 1 cm there): two readings
    of a still surface often differ by two cells, and with the gap not grown
    (``map_sigmas: 0``) the rule hides space behind them again and again.
    """
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    state = RobotState(robot, robot.home())
    table = ObjectSpec(
        name="table",
        shape="box",
        size=(1.2, 1.2, 0.02),
        pose=Pose(position=(0.4, 0, -0.01)),
    )
    box = ObjectSpec(
        name="box",
        shape="box",
        size=(0.2, 0.2, 0.2),
        pose=Pose(position=(0.6, 0.3, 0.1)),
    )
    axis = np.array([1.0, 0.0, 0.6]) / np.linalg.norm([1.0, 0.0, 0.6])
    far = CameraSpec(
        name="c",
        position=tuple(np.array([0.5, 0.0, 0.1]) + 2.5 * axis),
        target=(0.5, 0.0, 0.1),
    )

    def hidden(map_sigmas: float) -> int:
        camera = replace(far, noise=DepthNoise(map_sigmas=map_sigmas))
        spec = PerceptionSpec(
            source="depth_camera",
            camera=camera,
            bounds=((-0.3, -0.8, -0.05), (1.2, 0.8, 1.2)),
            max_range=3.0,
        )
        grid = OccupancyGrid(spec, geometry)
        render = DepthCamera(scene.client, camera)
        for k in range(60):
            grid.integrate(render.capture(), state, t=k / 15)
        return grid.hidden_cells

    with PybulletScene(robot, [table, box]) as scene:
        scene.set_configuration(robot.home())
        assert hidden(0.0) > 50
        assert hidden(3.0) <= 10


def test_a_camera_s_noise_section_loads_and_is_checked(tmp_path) -> None:
    """``noise:`` in YAML sets the model; a bad value is a located error."""
    base = "scenarios/cat_free_step.yaml"
    off = load_scenario(
        base,
        overrides={
            "perception.cameras.head.noise": "{enabled: false}",
            "perception.cameras.side.noise.dropout": "0.01",
        },
    ).spec.perception
    cameras = {c.name: c for c in off.all_cameras}
    assert not cameras["head"].noise.enabled
    assert cameras["side"].noise.dropout == 0.01
    assert cameras["left"].noise == DepthNoise()
    with pytest.raises(ScenarioError, match=r"perception\.cameras.*dropout.*\[0, 1\)"):
        load_scenario(base, overrides={"perception.cameras.head.noise.dropout": "1.5"})


def test_a_pixel_without_a_return_leaves_its_neighbours_seen() -> None:
    """The map's see-through ranges skip NaN pixels; a too-near one still stops.

    NaN (no return: an edge's far side, a dropout) takes the least of its
    neighbours' ranges and changes none of theirs; a pixel nearer than the
    minimum range stops its 3 x 3 neighbours (something is there); a block of
    NaN says nothing.
    """
    from cbp.perception.kernels import eroded_ranges

    depth = np.full((8, 8), 1.0)
    depth[:, 4:] = 1.5
    frame = _frame(depth)
    buffer = frame.depth.copy()
    buffer[2, 5] = np.nan  # a dropout on the far surface
    buffer[:, 4] = np.nan  # the edge's far side
    buffer[6:, 6:] = np.nan  # a block without returns
    nearest = replace(frame, min_range=0.5).buffer_limits[0]
    buffer[0, 0] = 0.5 * nearest  # nearer than the minimum range (0.5 m)
    ranges = eroded_ranges(buffer, NEAR, FAR, nearest, 1 - 1e-6, 1 + 1e-6)
    assert ranges[2, 5] == pytest.approx(1.5)
    assert ranges[3, 6] == pytest.approx(1.5)
    assert ranges[3, 4] == pytest.approx(1.0)  # as far as its nearer side
    assert ranges[7, 7] == -np.inf
    assert ranges[1, 1] == -np.inf  # beside the too-near pixel
    assert ranges[3, 2] == pytest.approx(1.0)
