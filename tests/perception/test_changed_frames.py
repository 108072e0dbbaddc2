# SPDX-License-Identifier: Apache-2.0
"""Frames integrated only where they changed leave the map a whole frame would.

``perception.whole_frame_every`` (default 15): a camera's frame from where its
last one was is integrated only at the pixels whose reading changed, the space
seen through only over the image's tiles holding one and the bricks whose
cells changed since the camera's last frame. On exact frames (no noise) that
is the same map, cell by cell, misses and all; on noisy frames the maps differ
at the noise's scale only. The compiled query of a map snapshot with the self
pairs (``query_with_self``) gives what the world's query gives apart.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy import ndimage

from cbp.collision.map_environment import OccupancyEnvironment
from cbp.perception.frame import DepthFrame
from cbp.perception.kernels import FREE
from cbp.perception.occupancy import OccupancyGrid
from cbp.perception.spec import DepthNoise
from cbp.scenario import load_scenario
from cbp.sim.camera import DepthCamera
from cbp.sim.raycast import RayCaster
from cbp.sim.scene import PybulletScene
from cbp.state import RobotState

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"
DATA = Path(__file__).parent / "data" / "shelf_frames.npz"


def _shelf(every: int, noise: bool = True):  # type: ignore[no-untyped-def]
    scenario = load_scenario(
        SCENARIOS / "cat_shelf_reach.yaml",
        overrides={
            "perception.source": "depth_camera",
            "perception.whole_frame_every": str(every),
        },
    )
    if not noise:
        spec = scenario.spec.perception
        exact = [
            dataclasses.replace(c, noise=DepthNoise(enabled=False), renderer="raycast")
            for c in spec.all_cameras
        ]
        perception = dataclasses.replace(spec, cameras=exact, camera=None)
        scenario = dataclasses.replace(
            scenario, spec=dataclasses.replace(scenario.spec, perception=perception)
        )
    return scenario


def test_exact_frames_integrated_where_they_changed_give_the_whole_frames_map() -> None:
    """On noise-free frames, integrating only the changes leaves every cell and miss as whole frames do."""
    scenario = _shelf(15, noise=False)
    spec = scenario.spec.perception
    geometry = scenario.new_world().geometry
    whole = OccupancyGrid(dataclasses.replace(spec, whole_frame_every=1), geometry)
    changed = OccupancyGrid(spec, geometry)
    state = RobotState(geometry.robot)
    q0 = scenario.q0.copy()
    q1 = q0 + np.array([0.5, 0.35, -0.3, 0.4, 0.2, -0.3, 0.3])
    # Still, moving, still; then the box is taken away (misses clear it).
    path = [q0] * 3 + [q0 + (q1 - q0) * s for s in np.linspace(0.1, 1.0, 6)]
    path += [q1] * 5
    with PybulletScene(scenario.robot, scenario.spec.world.objects, SCENARIOS) as scene:
        caster = RayCaster(scene.client)
        cameras = [
            DepthCamera(scene.client, c, scenario.robot, caster)
            for c in spec.all_cameras
        ]
        for n, q in enumerate(path):
            if n == len(path) - 3:
                scene.move_object("box", pin.SE3(np.eye(3), np.array([3.0, 3.0, 3.0])))
            scene.set_configuration(q)
            state.update(q)
            for camera in cameras:
                frame = camera.capture(state if camera.mounted else None)
                t = 0.1 * n
                a = whole.integrate(frame, state, t)
                b = changed.integrate(frame, state, t)
                where = f"frame {n}, camera {camera.name}"
                assert np.array_equal(whole.cells, changed.cells), where
                assert np.array_equal(whole.misses, changed.misses), where
                assert (a.inserted, a.hidden) == (b.inserted, b.hidden), where
                assert np.array_equal(
                    whole.moving_centres(t), changed.moving_centres(t)
                )
    assert changed.changed_frames > len(path) * (len(cameras) - 1) // 2
    assert whole.changed_frames == 0


def test_noisy_frames_integrated_where_they_changed_differ_at_the_noise_only() -> None:
    """On noisy recorded frames, a cell the whole frames block is free only beside one the changes block."""
    scenario = _shelf(15)
    geometry = scenario.new_world().geometry
    spec = scenario.spec.perception
    whole = OccupancyGrid(dataclasses.replace(spec, whole_frame_every=1), geometry)
    changed = OccupancyGrid(spec, geometry)
    state = RobotState(geometry.robot)
    data = np.load(DATA)
    differ = 0
    for n, t in enumerate(data["t"]):
        frame = DepthFrame(
            data[f"depth{n}"].astype(float),
            data[f"view{n}"],
            data[f"projection{n}"],
            float(data["near"][n]),
            float(data["far"][n]),
            str(data["camera"][n]),
            float(data["min_range"][n]),
        )
        state.update(data[f"q{n}"])
        whole.integrate(frame, state, float(t))
        changed.integrate(frame, state, float(t))
        blocked = changed.cells != FREE
        freed = (whole.cells != FREE) & ~blocked
        differ += int(np.count_nonzero(freed))
        beside = ndimage.binary_dilation(blocked, structure=np.ones((3, 3, 3), bool))
        assert not np.any(freed & ~beside), f"frame {n}"
    assert changed.changed_frames >= 8  # the test compares something
    assert differ > 0  # the noise shows


def test_the_map_query_with_the_self_pairs_is_the_world_query_apart() -> None:
    """A snapshot's one-pass query with the self pairs gives the contacts the world's query gives apart."""
    scenario = _shelf(1)
    world = scenario.new_world()
    grid = OccupancyGrid(scenario.spec.perception, world.geometry)
    state = RobotState(world.geometry.robot)
    data = np.load(DATA)
    for n in range(5):
        frame = DepthFrame(
            data[f"depth{n}"].astype(float),
            data[f"view{n}"],
            data[f"projection{n}"],
            float(data["near"][n]),
            float(data["far"][n]),
            str(data["camera"][n]),
            float(data["min_range"][n]),
        )
        state.update(data[f"q{n}"])
        grid.integrate(frame, state, float(data["t"][n]))
    env = grid.environment()

    class Apart(OccupancyEnvironment):
        def query_with_self(self, *args: object, **kwargs: object) -> None:
            return None

    # Obstacles measured nearer by shape (a snapshot of moving cells).
    nearer = np.linspace(0.0, 0.01, len(world.geometry.shapes))
    pairs = []
    for snapshot in (env, env.ahead(nearer)):
        apart = Apart.__new__(Apart)
        apart.__dict__.update(snapshot.__dict__)
        pairs.append((snapshot, apart))
    rng = np.random.default_rng(3)
    total = on_base = 0
    for k in range(40):
        q = data["q5"] + rng.normal(0.0, 0.15, len(data["q5"]))
        state.update(q)
        snapshot, apart = pairs[k % 2]
        one = world.query(state, snapshot)
        two = world.query(state, apart)
        total += len(one)
        # The fixed base touches the table's cells: those contacts are left out.
        found = snapshot.query(world.placed(state), world.margin(snapshot), 3)
        on_base += int(np.count_nonzero(found.shape == 0))
        assert not np.any((one.shape == 0) & (one.other_shape < 0))
        assert np.array_equal(one.shape, two.shape)
        assert np.array_equal(one.other_shape, two.other_shape)
        for name in ("point", "other_point", "normal", "distance"):
            np.testing.assert_allclose(
                getattr(one, name), getattr(two, name), atol=1e-9, err_msg=name
            )
    assert total > 40
    assert on_base > 40  # the base's contacts were there to leave out
