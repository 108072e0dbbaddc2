"""MotionBenchMaker's files, its scene sampler and its problems as scenarios.

The files here are written by the tests in MotionBenchMaker's format (a table
and a can of our own, not MotionBenchMaker's scenes).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from cbp.errors import ConfigError
from cbp.mbm import family_names, make_problem, read_family, write_problems
from cbp.mbm.cameras import mbm_cameras
from cbp.mbm.files import transform
from cbp.mbm.sampling import query_pose, sample_scene, variation_transform
from cbp.scenario import load_scenario

PACKAGE = "package://motion_bench_maker/configs"
#: The ready posture MotionBenchMaker's Panda file starts from (fingers first).
READY = [0.04, 0.04, 0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]


def _object(name: str, kind: str, size: list[float], position: list[float]) -> dict:
    return {
        "header": {"frame_id": "base_link"},
        "id": name,
        "primitives": [{"type": kind, "dimensions": size}],
        "primitive_poses": [{"position": position, "orientation": [0, 0, 0, 1]}],
    }


def _write(path: Path, document: object) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(document))


def write_checkout(
    root: Path, world: list[float] | None = None, can: list[float] | None = None
) -> Path:
    """A checkout with one family, ``shelf``: a board and a can 0.75 m ahead.

    ``world`` and ``can``: the World and the can's position variations [m].
    """
    configs = root / "configs"
    _write(
        configs / "problems" / "shelf_panda.yaml",
        {
            "robot_description": f"{PACKAGE}/robots/panda.yaml",
            "scene": f"{PACKAGE}/scenes/shelf/scene.yaml",
            "queries": f"{PACKAGE}/scenes/shelf/queries.yaml",
            "variation": f"{PACKAGE}/scenes/shelf/variation.yaml",
            "sensors": f"{PACKAGE}/scenes/shelf/sensors.yaml",
            "planning_group": "panda_arm",
            "samples": 10,
            "base_offset": {"position": [0, 0, -0.5], "orientation": [0, 0, 0, 1]},
            # The query frame: 8 cm behind the flange, its x along the hand's z.
            "ee_offset": {
                "position": [0, 0, -0.08],
                "orientation": [-0.5, -0.5, -0.5, 0.5],
            },
        },
    )
    _write(
        configs / "robots" / "panda.yaml",
        {
            "robot_state": {
                "joint_state": {
                    "name": [
                        "panda_finger_joint1",
                        "panda_finger_joint2",
                        *(f"panda_joint{i}" for i in range(1, 8)),
                    ],
                    "position": READY,
                }
            }
        },
    )
    shelf = configs / "scenes" / "shelf"
    _write(
        shelf / "scene.yaml",
        {
            "world": {
                "collision_objects": [
                    _object("Can1", "cylinder", [0.12, 0.03], [0.75, 0.0, 0.95]),
                    _object("board", "box", [0.3, 0.6, 0.04], [0.8, 0.0, 0.87]),
                ]
            }
        },
    )
    _write(
        shelf / "variation.yaml",
        [
            {
                "names": ["World"],
                "position": world or [0.0, 0.0, 0.0],
                "orientation": [0, 0, 0],
                "type": "uniform",
            },
            {
                "names": ["Can1", "Missing"],
                "position": can or [0.0, 0.0, 0.0],
                "orientation": [0, 0, 0],
                "type": "uniform",
            },
        ],
    )
    _write(
        shelf / "queries.yaml",
        {
            "goal_queries": [
                {
                    "objects": ["Can1"],
                    "tag": "Front",
                    "offset": {
                        "position": [-0.2, 0.0, 0.05],
                        "orientation": [0, 0, 0, 1],
                        "position_tol": [0.01, 0.01, 0.01],
                        "orientation_tol": [0.01, 0.01, 0.01],
                    },
                    "attached": "False",
                }
            ]
        },
    )
    _write(
        shelf / "sensors.yaml",
        {
            "camera_config": f"{PACKAGE}/sensors/camera.yaml",
            "look_objects": [{"name": "board", "position": [0.0, 0.0, 0.2]}],
            "cam_points": [[0.0, 0.0, 1.2], [0.0, 0.0, 1.4]],
            "resolution": 0.02,
        },
    )
    _write(
        configs / "sensors" / "camera.yaml",
        {
            "focal_length_x": 300.0,
            "focal_length_y": 300.0,
            "width": 320,
            "height": 240,
            "z_near": 0.05,
            "z_far": 4.0,
        },
    )
    return root


def test_a_family_is_read_with_motion_bench_makers_conventions(tmp_path: Path) -> None:
    """Cylinders are [height, radius], quaternions [x, y, z, w], fingers kept."""
    family = read_family(write_checkout(tmp_path), "shelf")
    can = family.objects[0]
    assert (can.name, can.shape, can.dimensions) == ("Can1", "cylinder", (0.12, 0.03))
    np.testing.assert_allclose(can.pose[:3, 3], [0.75, 0.0, 0.95])
    np.testing.assert_allclose(family.base_offset[:3, 3], [0.0, 0.0, -0.5])
    # The query frame's x is the tip's z: the hand approaches along it.
    np.testing.assert_allclose(
        np.linalg.inv(family.ee_offset)[:3, 2], [1, 0, 0], atol=1e-9
    )
    assert [q.name for q in family.goal_queries] == ["Can1_Front"]
    assert family.start_state["panda_joint4"] == -2.356
    assert family.sensors.fov_deg == pytest.approx(43.6, abs=0.1)
    assert family_names(tmp_path) == ["shelf"]


def test_an_unknown_family_names_the_choices(tmp_path: Path) -> None:
    """The error lists the families the checkout has."""
    with pytest.raises(ConfigError, match=r"no family 'cage'.*choices: shelf"):
        read_family(write_checkout(tmp_path), "cage")
    with pytest.raises(ConfigError, match="not a MotionBenchMaker checkout"):
        write_problems(tmp_path / "nowhere", tmp_path / "out", 1)


def test_the_nominal_scene_moves_by_the_base_offset(tmp_path: Path) -> None:
    """Without variation every object is at base_offset times its pose."""
    family = read_family(write_checkout(tmp_path), "shelf")
    objects, whole = sample_scene(family, np.random.default_rng(0))
    np.testing.assert_allclose(whole, family.base_offset)
    np.testing.assert_allclose(objects[0].pose[:3, 3], [0.75, 0.0, 0.45])


def test_the_world_variation_turns_the_scene_about_the_base(tmp_path: Path) -> None:
    """A yaw-only World variation keeps each object's distance from the z axis."""
    root = write_checkout(tmp_path)
    variations = root / "configs" / "scenes" / "shelf" / "variation.yaml"
    entries = yaml.safe_load(variations.read_text())
    entries[0]["orientation"] = [0.0, 0.0, 1.5]
    variations.write_text(yaml.safe_dump(entries))
    family = read_family(root, "shelf")
    turned = []
    for seed in range(20):
        objects, _ = sample_scene(family, np.random.default_rng(seed))
        p = objects[0].pose[:3, 3]
        assert np.hypot(p[0], p[1]) == pytest.approx(0.75)
        assert p[2] == pytest.approx(0.45)
        turned.append(np.arctan2(p[1], p[0]))
    assert max(turned) > 0.5
    assert min(turned) < -0.5
    assert max(np.abs(turned)) <= 1.5


def test_object_variations_move_each_object_in_its_own_frame(tmp_path: Path) -> None:
    """Uniform within the bounds, drawn per object, seeded, along the object's axes."""
    family = read_family(write_checkout(tmp_path, can=[0.0, 0.2, 0.0]), "shelf")
    a, _ = sample_scene(family, np.random.default_rng(3))
    b, _ = sample_scene(family, np.random.default_rng(3))
    np.testing.assert_array_equal(a[0].pose, b[0].pose)  # the same seed, the same scene
    ys = [
        sample_scene(family, np.random.default_rng(s))[0][0].pose[1, 3]
        for s in range(50)
    ]
    assert max(np.abs(ys)) <= 0.2
    assert np.ptp(ys) > 0.2
    np.testing.assert_allclose(a[1].pose[:3, 3], [0.8, 0.0, 0.37])  # the board stays
    # An object turned a quarter about z moves along the world's x for its y.
    variation = family.variations[1]
    turned = transform([0.0, 0.0, 0.0], [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)])
    moved = turned @ variation_transform(variation, np.random.default_rng(1))
    assert abs(moved[1, 3]) < 1e-12
    assert abs(moved[0, 3]) > 0.0


def test_a_variation_of_unknown_type_names_the_choices(tmp_path: Path) -> None:
    """Only uniform and gaussian are known."""
    family = read_family(write_checkout(tmp_path), "shelf")
    variation = family.variations[0]
    odd = type(variation)(
        variation.names, variation.position, variation.orientation, "beta"
    )
    with pytest.raises(ConfigError, match="choose uniform or gaussian"):
        variation_transform(odd, np.random.default_rng(0))


def test_the_tip_goes_to_the_query_pose_times_the_inverse_ee_offset(
    tmp_path: Path,
) -> None:
    """Can's pose x offset x inverse(ee_offset): the flange 8 cm past the query point."""
    family = read_family(write_checkout(tmp_path), "shelf")
    objects, _ = sample_scene(family, np.random.default_rng(0))
    tip = query_pose(family.goal_queries[0], objects, family.ee_offset)
    np.testing.assert_allclose(tip[:3, 3], [0.75 - 0.2 + 0.08, 0.0, 0.5], atol=1e-9)
    np.testing.assert_allclose(tip[:3, 2], [1.0, 0.0, 0.0], atol=1e-9)


def test_a_valid_problem_is_two_loadable_scenarios(tmp_path: Path) -> None:
    """Start and goal as MotionBenchMaker's; both camera variants load."""
    root = write_checkout(tmp_path / "mbm")
    family = read_family(root, "shelf")
    out = tmp_path / "out"
    out.mkdir()
    problem = make_problem(family, 0, 0, out)
    assert problem is not None
    ours = load_scenario(out / "mbm_shelf_0.yaml")
    theirs = load_scenario(out / "mbm_shelf_0_mbm_cameras.yaml")
    assert ours.spec.perception.source == "ground_truth"
    assert [c.name for c in ours.spec.perception.cameras] == [
        "head",
        "side",
        "left",
        "front",
        "wrist",
    ]
    assert len(theirs.spec.perception.cameras) == 2  # one look point, two cameras
    np.testing.assert_allclose(ours.q0, READY[2:])
    # The hand's goal: the flange's, 10 cm back along the approach.
    goal = ours.spec.goal.keyframes[0].pose.position
    np.testing.assert_allclose(goal, [0.75 - 0.2 + 0.08 - 0.1, 0.0, 0.5], atol=1e-4)
    world = ours.world_for_run()
    clearance = world.environment.clearance(
        np.array([c.position for c in ours.spec.perception.cameras[:4]])
    )
    assert np.all(clearance >= 0.05)


def test_an_unreachable_goal_gives_no_problem(tmp_path: Path) -> None:
    """A can 2 m away is beyond the arm: the attempt leaves nothing behind."""
    root = write_checkout(tmp_path / "mbm")
    scene = root / "configs" / "scenes" / "shelf" / "scene.yaml"
    scene.write_text(scene.read_text().replace("0.75", "2.75"))
    out = tmp_path / "out"
    out.mkdir()
    assert make_problem(read_family(root, "shelf"), 0, 0, out) is None
    assert not any(out.iterdir())


def test_motion_bench_makers_cameras_look_at_the_sampled_objects(
    tmp_path: Path,
) -> None:
    """Each camera point looks at the look point; all together near 75 frames/s."""
    family = read_family(write_checkout(tmp_path), "shelf")
    objects, _ = sample_scene(family, np.random.default_rng(0))
    cameras = mbm_cameras(family, objects)
    assert [c["position"] for c in cameras] == [[0.0, 0.0, 1.2], [0.0, 0.0, 1.4]]
    assert all(c["target"] == [0.8, 0.0, 0.57] for c in cameras)
    assert sum(c["rate_hz"] for c in cameras) == pytest.approx(75.0)


def test_cbp_scenes_writes_motion_bench_maker_problems(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``cbp scenes --mbm`` prints each problem's file; a bad family exits 2."""
    from cbp.cli import main

    root = write_checkout(tmp_path / "mbm")
    out = tmp_path / "out"
    assert main(["scenes", "--mbm", str(root), "--count", "1", "--out", str(out)]) == 0
    assert capsys.readouterr().out.split() == [str(out / "mbm_shelf_0.yaml")]
    args = ["scenes", "--mbm", str(root), "--family", "cage", "--out", str(out)]
    assert main(args) == 2
    assert "choices: shelf" in capsys.readouterr().err
