"""``cbp robot init`` on every arm pybullet_data ships: no hand edits needed."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pinocchio as pin
import pybullet_data
import pytest
import yaml

from cbp.cli import main
from cbp.errors import ScenarioError
from cbp.scenario import load_scenario
from cbp.urdf_files import resolve_mesh

DATA = Path(pybullet_data.getDataPath())
_MOVABLE = re.compile(r'type="(?:revolute|prismatic|continuous)"')


def _pybullet_arms() -> tuple[list[str], list[str]]:
    """URDFs under pybullet_data with a chain of six or more joints: the arms.

    Returns:
        The arms, and the arms whose URDF names mesh files pybullet_data lacks.
    """
    arms, incomplete = [], []
    for urdf in sorted(DATA.rglob("*.urdf")):
        if len(_MOVABLE.findall(urdf.read_text(errors="replace"))) < 6:
            continue
        try:
            model = pin.buildModelFromUrdf(str(urdf))
        except (RuntimeError, ValueError):
            continue
        depth = [0] * model.njoints
        for j in range(1, model.njoints):
            depth[j] = depth[model.parents[j]] + 1
        if max(depth) < 6:
            continue
        meshes = re.findall(r'<mesh filename="([^"]+)"', urdf.read_text())
        missing = [m for m in meshes if resolve_mesh(m, urdf.parent) is None]
        (incomplete if missing else arms).append(urdf.relative_to(DATA).as_posix())
    return arms, incomplete


ARMS, INCOMPLETE = _pybullet_arms()

#: The hand each arm's robot.yaml must move, and the joints it must lock.
HANDS = {
    "franka_panda/panda.urdf": (
        "panda_hand",
        {"panda_finger_joint1", "panda_finger_joint2"},
    ),
    "xarm/xarm6_with_gripper.urdf": (
        "xarm_gripper_base_link",
        {
            "drive_joint",
            "left_finger_joint",
            "left_inner_knuckle_joint",
            "right_inner_knuckle_joint",
            "right_outer_knuckle_joint",
            "right_finger_joint",
        },
    ),
    "xarm/xarm6_robot.urdf": ("link6", set()),
    "kuka_iiwa/model.urdf": ("lbr_iiwa_link_7", set()),
}

#: The hand passes a post: from one side of it to the other, in front of it.
POST_SCENARIO = """\
name: post
include: cat
robot: {name: arm}
duration: 6.0
goal:
  type: keyframes
  keyframes:
    - {t: 0.3, pose: {position: [0.35, -0.25, 0.25], rpy_deg: [180, 0, 0]}}
    - {t: 1.0, pose: {position: [0.35, 0.25, 0.25], rpy_deg: [180, 0, 0]}}
world:
  objects:
    - {name: post, shape: cylinder, size: [0.04, 0.3], pose: {position: [0.45, 0.0, 0.15]}}
"""


def _init(urdf: str, out: Path, *extra: str) -> None:
    command = ["robot", "init", str(DATA / urdf), "--out", str(out)]
    status = main(["-q", *command, "--samples", "50", *extra])
    assert status == 0


def test_every_known_arm_is_enumerated() -> None:
    """The enumeration finds the Panda, the xArm6 (with and without gripper) and the iiwa."""
    assert set(HANDS) <= set(ARMS), ARMS
    assert INCOMPLETE == [
        "kuka_iiwa/model_for_sdf.urdf"
    ]  # its meshes/coarse/ is not shipped


def test_an_arm_without_its_meshes_is_refused_naming_the_mesh(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`cbp robot init` on a URDF whose collision meshes are missing lists them all, and writes nothing."""
    urdf = DATA / "kuka_iiwa" / "model_for_sdf.urdf"
    status = main(["-q", "robot", "init", str(urdf), "--out", str(tmp_path / "arm")])
    assert status == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{urdf}: 8 problems:\n")
    assert (
        "  line 76: link 'lbr_iiwa_link_0': cannot find its collision mesh "
        "'meshes/coarse/link_0.stl'\n"
    ) in err
    assert not (tmp_path / "arm").exists()


@pytest.mark.parametrize("urdf", ARMS)
def test_robot_init_then_check_passes_with_cat_after_moving_the_folder(
    urdf: str, tmp_path: Path
) -> None:
    """`cbp robot init` + include: cat loads, with the folder moved away from the URDF."""
    _init(urdf, tmp_path / "made" / "arm")
    shutil.move(tmp_path / "made" / "arm", tmp_path / "arm")  # portable paths
    document = yaml.safe_load((tmp_path / "arm" / "robot.yaml").read_text())
    assert document["urdf"] == "robot.urdf"
    hand, gripper = HANDS.get(urdf, (None, None))
    if hand is not None:
        assert document["end_effector"] == hand
        assert set(document.get("locked_joints", {})) == gripper
    (tmp_path / "s.yaml").write_text(POST_SCENARIO)
    assert main(["-q", "check", str(tmp_path / "s.yaml")]) == 0


@pytest.mark.slow
@pytest.mark.parametrize("urdf", ARMS)
def test_each_arm_reaches_past_a_post_with_cat_at_zero_force(
    urdf: str, tmp_path: Path
) -> None:
    """With include: cat and no hand edit, the hand passes the post without contact."""
    _init(urdf, tmp_path / "arm")
    (tmp_path / "s.yaml").write_text(POST_SCENARIO)
    out = tmp_path / "out"
    assert main(["-q", "run", str(tmp_path / "s.yaml"), "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())["cat"]
    assert metrics["peak_contact_force_n"] == 0.0
    assert metrics["reached"], metrics


def test_a_kept_gripper_is_warned_about_and_the_margin_error_names_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Fingers kept in the QP: a warning at init, then an error naming joint, range, files."""
    _init("franka_panda/panda.urdf", tmp_path / "arm", "--control-gripper")
    out = capsys.readouterr().out
    assert (
        "warning: 'include: cat' keeps joints 0.03 from their limits, more than half "
        "the range of panda_finger_joint1 [0, 0.04], panda_finger_joint2 [0, 0.04]"
    ) in out
    (tmp_path / "s.yaml").write_text(POST_SCENARIO)
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "s.yaml")
    (problem,) = info.value.problems
    assert problem.startswith("line 2 (include: cat) -> ")
    assert "cat.yaml, line 38: constraints[0].params.margin" in problem
    assert (
        "margin 0.03 is more than half the range of panda_finger_joint1 [0, 0.04], "
        f"panda_finger_joint2 [0, 0.04] of robot 'panda' ({tmp_path / 'arm' / 'robot.yaml'})"
    ) in problem


def test_robot_yaml_problems_are_located_in_robot_yaml(tmp_path: Path) -> None:
    """Bad names in robot.yaml are reported at robot.yaml's lines, all at once."""
    _init("franka_panda/panda.urdf", tmp_path / "arm")
    path = tmp_path / "arm" / "robot.yaml"
    text = path.read_text()
    text = text.replace("end_effector: panda_hand", "end_effector: panda_hnd")
    text = text.replace("home:\n", "home:\n  panda_finger_joint1: 0.01\n")
    path.write_text(text)
    lines = text.splitlines()
    (tmp_path / "s.yaml").write_text(POST_SCENARIO)
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "s.yaml")
    ee = lines.index("end_effector: panda_hnd") + 1
    finger = lines.index("  panda_finger_joint1: 0.01") + 1
    assert sorted(info.value.problems) == sorted(
        [
            f"{path}, line {ee}: end_effector: no frame 'panda_hnd' in robot.urdf; "
            "close matches: panda_hand, panda_hand_joint, panda_link8",
            f"{path}, line {finger}: home.panda_finger_joint1: joint "
            "'panda_finger_joint1' is locked (locked_joints), so it is not in the "
            "model: remove it here",
        ]
    )


def test_an_unknown_key_in_robot_yaml_is_located_there(tmp_path: Path) -> None:
    """A schema problem of robot.yaml names robot.yaml and its line, not robot.name."""
    _init("kuka_iiwa/model.urdf", tmp_path / "arm")
    path = tmp_path / "arm" / "robot.yaml"
    path.write_text(path.read_text() + "end_efector: x\n")
    line = len(path.read_text().splitlines())
    (tmp_path / "s.yaml").write_text(POST_SCENARIO)
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "s.yaml")
    (problem,) = info.value.problems
    assert problem.startswith(f"{path}, line {line}: end_efector: unknown key")


def test_copied_meshes_keep_their_materials(tmp_path: Path) -> None:
    """The copy holds every mesh the URDF names, with .obj materials and the licence."""
    _init("franka_panda/panda.urdf", tmp_path / "arm")
    urdf = (tmp_path / "arm" / "robot.urdf").read_text()
    names = re.findall(r'<mesh filename="([^"]+)"', urdf)
    assert names
    assert all((tmp_path / "arm" / name).is_file() for name in names)
    assert (tmp_path / "arm" / "meshes" / "visual" / "link1.mtl").is_file()
    assert (tmp_path / "arm" / "LICENSE.txt").is_file()
    assert "package://" not in urdf


def test_no_copy_names_the_urdf_where_it_is(tmp_path: Path) -> None:
    """--no-copy writes a path relative to the folder and copies nothing."""
    _init("xarm/xarm6_robot.urdf", tmp_path / "arm", "--no-copy")
    document = yaml.safe_load((tmp_path / "arm" / "robot.yaml").read_text())
    assert (tmp_path / "arm" / document["urdf"]).resolve() == (
        DATA / "xarm" / "xarm6_robot.urdf"
    ).resolve()
    assert sorted(p.name for p in (tmp_path / "arm").iterdir()) == ["robot.yaml"]


def test_a_second_init_into_the_same_folder_is_refused(tmp_path: Path) -> None:
    """`cbp robot init` does not overwrite a robot.yaml."""
    _init("kuka_iiwa/model.urdf", tmp_path / "arm")
    status = main(
        [
            "-q",
            "robot",
            "init",
            str(DATA / "kuka_iiwa/model.urdf"),
            "--out",
            str(tmp_path / "arm"),
        ]
    )
    assert status == 2


def test_trailing_finger_joints_of_a_single_chain_are_the_gripper(
    tmp_path: Path,
) -> None:
    """On one chain, trailing joints named like fingers are locked; their parent is the hand."""
    from cbp.robot_init import describe_urdf

    links = "".join(f'<link name="l{i}"/>' for i in range(5))
    joints = "".join(
        f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/>'
        f'<child link="l{i}"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>'
        '<limit lower="-2" upper="2" effort="1" velocity="1"/></joint>'
        for i in range(1, 4)
    )
    finger = (
        '<joint name="jaw_joint" type="prismatic"><parent link="l3"/>'
        '<child link="l4"/><axis xyz="1 0 0"/>'
        '<limit lower="0" upper="0.02" effort="1" velocity="1"/></joint>'
    )
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(f'<robot name="toy">{links}{joints}{finger}</robot>')
    setup = describe_urdf(urdf, samples=0)
    assert setup.document["end_effector"] == "l3"
    assert setup.document["locked_joints"] == {"jaw_joint": 0.01}
    assert list(setup.document["home"]) == ["j1", "j2", "j3"]
