"""The ray-cast camera: the tiny renderer's pixels, true primitive surfaces, new bodies."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cbp.perception.frame import DepthFrame
from cbp.perception.spec import CameraSpec, DepthNoise
from cbp.scenario import ObjectSpec, load_scenario
from cbp.sim.bullet import pb
from cbp.sim.camera import DepthCamera
from cbp.sim.raycast import RayCaster
from cbp.sim.scene import PybulletScene
from cbp.spatial import Pose
from cbp.state import RobotState

SCENARIOS = Path(__file__).parents[2] / "scenarios"
EXACT = DepthNoise(enabled=False)
CAST = "raycast"
W, H = 128, 96

#: Depths agree within this [m] ...
TOLERANCE = 1e-3
#: ... on at least this fraction of all the pixels (both see nothing, or both a
#: surface that near), and of each image's. The rest lie on silhouette edges,
#: or on triangles crossing the clipping plane, whose depth the tiny renderer
#: gets wrong by about 1 mm (the shelf's board over the camera ``c3``: the ray
#: cast's depth there is the plane's, as the true-surface test below checks).
#: Measured: 99.9 % in all, at least 98.98 % per image (36 images at 128 x 96).
AGREEING, AGREEING_PER_IMAGE = 0.995, 0.985


def _cameras() -> list[CameraSpec]:
    """Fixed cameras around the table, one close, and a camera on the hand."""
    fixed = [
        ((0.55, -0.6, 1.2), (0.55, 0.05, 0.03)),
        ((0.5, 1.0, 0.3), (0.5, -0.3, 0.08)),
        ((-0.35, 0.0, 1.15), (0.55, 0.0, 0.15)),
        ((0.84, -0.25, 0.40), (0.5, 0.05, 0.25)),
        ((1.3, 0.4, 0.5), (0.3, 0.0, 0.3)),
    ]
    specs = [
        CameraSpec(
            name=f"c{i}", position=p, target=t, width=W, height=H, fov_deg=70.0,
            far=2.5, noise=EXACT, renderer=CAST,
        )
        for i, (p, t) in enumerate(fixed)
    ]  # fmt: skip
    offset = Pose(position=(0.06, 0.0, 0.03), rpy_deg=(0.0, 25.0, 0.0))
    return [
        *specs,
        CameraSpec(
            name="wrist", parent="end_effector", offset=offset, width=W, height=H,
            fov_deg=80.0, near=0.05, far=1.5, noise=EXACT, renderer=CAST,
        ),
    ]  # fmt: skip


def _agreement(tiny: DepthFrame, cast: DepthFrame) -> np.ndarray:
    """Which pixels agree (H, W).

    Both background, both nearer than the minimum range, or both a range and
    within the tolerance.
    """
    a, b = tiny.ranges(), cast.ranges()
    with np.errstate(invalid="ignore"):
        same = (np.isinf(a) & np.isinf(b)) | (np.isnan(a) & np.isnan(b))
        same |= np.abs(a - b) <= TOLERANCE
    return np.asarray(same)


@pytest.mark.parametrize("scene", ["cat_boards", "cat_shelf_reach"])
def test_ray_cast_pixels_match_the_tiny_renderer(scene: str) -> None:
    """On boxes and the Panda's meshes, >= 99.5 % of pixels agree within 1 mm."""
    scenario = load_scenario(SCENARIOS / f"{scene}.yaml")
    robot = scenario.robot
    rng = np.random.default_rng(3)
    lower, upper = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    configurations = [scenario.q0] + [
        scenario.q0 + 0.3 * rng.uniform(-1.0, 1.0, robot.nq) for _ in range(2)
    ]
    agree = []
    with PybulletScene(robot, list(scenario.spec.world.objects)) as sim:
        caster = RayCaster(sim.client)
        state = RobotState(robot)
        for q in configurations:
            q = np.clip(q, lower, upper)
            sim.set_configuration(q)
            state.update(q)
            for spec in _cameras():
                tiny = DepthCamera(sim.client, replace(spec, renderer="tiny"), robot)
                cast = DepthCamera(sim.client, spec, robot, caster)
                at = state if spec.parent else None
                agree.append(_agreement(tiny.capture(at), cast.capture(at)))
    assert np.mean(agree) >= AGREEING
    assert min(np.mean(a) for a in agree) >= AGREEING_PER_IMAGE


PRIMITIVES = [
    ObjectSpec(
        name="block", shape="box", size=(0.3, 0.5, 0.1),
        pose=Pose(position=(0.5, 0.0, 0.05), rpy_deg=(0.0, 0.0, 20.0)),
    ),
    ObjectSpec(name="ball", shape="sphere", size=(0.08,), pose=Pose(position=(0.6, -0.2, 0.3))),
    ObjectSpec(
        name="can", shape="cylinder", size=(0.05, 0.2),
        pose=Pose(position=(0.6, 0.15, 0.25), rpy_deg=(30.0, 20.0, 0.0)),
    ),
]  # fmt: skip


def _surface_distance(points: np.ndarray) -> np.ndarray:
    """Distance of world points (n, 3) to the nearest primitive's surface [m]."""
    block, ball, can = PRIMITIVES
    B = block.pose.to_se3()
    local = np.abs((points - B.translation).dot(B.rotation)) - np.array(
        [0.15, 0.25, 0.05]
    )
    outside = np.linalg.norm(np.maximum(local, 0.0), axis=1)
    to_block = np.where(np.any(local > 0, axis=1), outside, -np.max(local, axis=1))
    to_ball = np.abs(np.linalg.norm(points - ball.pose.position, axis=1) - 0.08)
    M = can.pose.to_se3()
    local = (points - M.translation).dot(M.rotation)
    radial = np.linalg.norm(local[:, :2], axis=1) - 0.05
    axial = np.abs(local[:, 2]) - 0.1
    outside = np.hypot(np.maximum(radial, 0.0), np.maximum(axial, 0.0))
    to_can = np.where((radial > 0) | (axial > 0), outside, -np.maximum(radial, axial))
    return np.asarray(np.minimum(np.minimum(to_ball, to_can), to_block))


def test_primitives_are_cast_on_their_true_surfaces() -> None:
    """Every pixel seeing a box, sphere or cylinder lies on its surface (0.1 mm)."""
    robot = load_scenario(SCENARIOS / "cat_boards.yaml").robot
    spec = CameraSpec(
        name="c", position=(1.4, 0.0, 0.6), target=(0.6, 0.0, 0.25), width=W,
        height=H, fov_deg=50.0, far=2.5, noise=EXACT, renderer=CAST,
    )  # fmt: skip
    with PybulletScene(robot, PRIMITIVES) as sim:
        pb.removeBody(sim.robot_id, physicsClientId=sim.client)
        points, hit = DepthCamera(sim.client, spec).capture().points()
        seen = points[hit]
    assert len(seen) > 1000  # the shapes fill part of the image
    assert np.max(_surface_distance(seen)) < 1e-4


def test_bodies_added_or_replaced_later_are_seen_at_the_next_capture() -> None:
    """An object that appears is in the next image; one removed is not."""
    robot = load_scenario(SCENARIOS / "cat_boards.yaml").robot
    spec = CameraSpec(
        name="c", position=(1.4, 0.0, 0.6), target=(0.6, 0.0, 0.25), width=W,
        height=H, fov_deg=50.0, far=2.5, noise=EXACT, renderer=CAST,
    )  # fmt: skip
    with PybulletScene(robot, []) as sim:
        camera = DepthCamera(sim.client, spec, robot)
        before = camera.capture().ranges()
        sim.add_object(PRIMITIVES[1], PRIMITIVES[1].pose.to_se3())
        after = camera.capture().ranges()
        # The ball's body removed and a can added (PyBullet may reuse its id).
        sim.remove_object("ball")
        sim.add_object(PRIMITIVES[2], PRIMITIVES[2].pose.to_se3())
        points, hit = camera.capture().points()
    changed = ~np.isclose(before, after, equal_nan=True)
    assert changed.sum() > 100
    assert np.all(after[changed] < 1.4)  # the ball, in front of what was there
    seen = points[hit]
    ball = PRIMITIVES[1]
    on_ball = np.abs(np.linalg.norm(seen - ball.pose.position, axis=1) - 0.08) < 1e-3
    assert not on_ball.any()
    assert np.count_nonzero(_surface_distance(seen) < 1e-4) > 100  # the can


def test_a_shape_that_cannot_be_cast_is_named() -> None:
    """A visual shape the caster does not know raises an error naming it."""
    robot = load_scenario(SCENARIOS / "cat_boards.yaml").robot
    with PybulletScene(robot, []) as sim:
        c = sim.client
        plane = pb.createVisualShape(pb.GEOM_PLANE, physicsClientId=c)
        pb.createMultiBody(baseVisualShapeIndex=plane, physicsClientId=c)
        view = np.eye(4)
        with pytest.raises(ValueError, match="visual shape type 6"):
            RayCaster(c).render(view, np.eye(4), 8, 8, 0.01, 1.0)
