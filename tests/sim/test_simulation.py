"""The simulated Panda on each engine: holding, following, contact, objects in time."""

from __future__ import annotations

import sys
from importlib.util import find_spec
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from cbp.errors import ConfigError
from cbp.executors import load_executor
from cbp.metrics import run_metrics
from cbp.robot import RobotModel
from cbp.scenario.scene import ObjectMotion, ObjectSpec
from cbp.sim.simulation import Simulation
from cbp.sim.trajectory import time_parameterize
from cbp.spatial import Pose
from tests.conftest import load_virtual

ROOT = Path(__file__).resolve().parents[2]
NO_MUJOCO = find_spec("mujoco") is None
SIMULATORS = [
    "pybullet",
    pytest.param(
        "mujoco",
        marks=pytest.mark.skipif(
            NO_MUJOCO, reason="needs the mujoco extra: pip install -e '.[mujoco]'"
        ),
    ),
]
#: A box under the home pose's hand: its top face at z = 0.45 m.
BOX = ObjectSpec(
    name="box", shape="box", size=(0.3, 0.3, 0.3), pose=Pose(position=(0.35, 0.0, 0.3))
)


@pytest.fixture(scope="module")
def panda() -> RobotModel:
    return RobotModel.load("franka_panda")


@pytest.mark.parametrize("simulator", SIMULATORS)
def test_holds_its_pose_against_gravity(panda: RobotModel, simulator: str) -> None:
    """The impedance law with the same model's dynamics holds the home pose."""
    q0 = panda.home()
    with Simulation(panda, [], q0, simulator=simulator) as sim:
        sim.run_until(0.3)
        assert sim.steps == 300
        np.testing.assert_allclose(sim.q, q0, atol=1e-4)


@pytest.mark.parametrize("simulator", SIMULATORS)
def test_follows_a_spliced_trajectory(panda: RobotModel, simulator: str) -> None:
    """Tracking error stays small; the robot ends at rest at the last point."""
    q0 = panda.home()
    q1 = q0 + np.array([0.6, 0.3, -0.4, 0.4, 0.5, -0.3, 0.6])
    vmax, amax = 0.5 * panda.velocity_limits, 0.5 * panda.acceleration_limits
    with Simulation(panda, [], q0, simulator=simulator) as sim:
        traj = time_parameterize(
            np.linspace(q0, q1, 100), 0.1, 0 * q0, 0 * q0, vmax, amax
        )
        assert traj is not None
        sim.follow(sim.trajectory.splice(traj))
        sim.run_until(traj.end_time + 0.2)
        rec = sim.recording()
        assert np.max(np.abs(rec["q"] - rec["q_cmd"])) < 5e-3
        np.testing.assert_allclose(sim.q, q1, atol=1e-3)
        np.testing.assert_allclose(sim.v, 0.0, atol=1e-2)
        assert rec["contact_force"].max() == 0.0


def _cube(folder: Path, edge: float) -> str:
    """An OBJ file of a cube of ``edge`` [m] centred on its origin; its name."""
    h = 0.5 * edge
    corners = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    faces = [
        (1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2),
        (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4),
    ]  # fmt: skip
    lines = [f"v {x} {y} {z}" for x, y, z in corners]
    lines += [f"f {a} {b} {c}\nf {a} {c} {d}" for a, b, c, d in faces]
    (folder / "cube.obj").write_text("\n".join(lines) + "\n")
    return "cube.obj"


@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize("shape", ["box", "mesh"])
def test_measures_contact_force_when_pushed_into_a_box(
    panda: RobotModel, simulator: str, shape: str, tmp_path: Path
) -> None:
    """Commanded through a box (a primitive or a mesh), the hand presses on it."""
    box = BOX
    if shape == "mesh":
        box = ObjectSpec(
            name="box", shape="mesh", file=_cube(tmp_path, 0.3), pose=BOX.pose
        )
    q0 = panda.home()
    # Joint 2 leans forward: the hand goes down into the box's top face.
    q1 = q0.copy()
    q1[1] += 0.5
    with Simulation(panda, [box], q0, folder=tmp_path, simulator=simulator) as sim:
        vmax, amax = 0.3 * panda.velocity_limits, 0.3 * panda.acceleration_limits
        traj = time_parameterize(
            np.linspace(q0, q1, 50), 0.0, 0 * q0, 0 * q0, vmax, amax
        )
        assert traj is not None
        sim.follow(traj)
        sim.run_until(traj.end_time + 0.2)
        rec = sim.recording()
    assert rec["contact_force"].max() > 1.0
    assert rec["wrist_force"].max() > 1.0
    assert 0.0 < rec["penetration"].max() < 0.02
    # The joints' effort limits hold the hand's push: it settles where they do.
    assert 250.0 < rec["wrist_force"][-1] < 350.0


@pytest.mark.parametrize("simulator", SIMULATORS)
def test_a_joint_pushed_into_its_limit_stops_there(
    panda: RobotModel, simulator: str
) -> None:
    """40 N m on joint 4 towards its upper limit: a hard stop, as PyBullet's."""
    q0 = panda.home()
    q0[3] = -0.3  # 0.23 rad below its limit
    push = np.zeros(7)
    push[3] = 40.0
    with Simulation(panda, [], q0, simulator=simulator) as sim:
        sim.set_torque_controller(lambda t, q, v: sim.gravity(q) + push)
        sim.run_until(1.0)
        past = sim.recording()["q"][:, 3] - panda.upper_limits[3]
    assert past.max() < 0.01  # rad; MuJoCo's default soft limit: 0.074
    assert past[-1] < 0.001  # rad; MuJoCo's default soft limit: 0.0037


def _cup(folder: Path) -> str:
    """An OBJ file of an open box, 0.3 x 0.3 x 0.2 m, its centre at its origin."""
    x, y, z = 0.15, 0.15, 0.1
    corners = [(a * x, b * y, c * z) for c in (-1, 1) for b in (-1, 1) for a in (-1, 1)]
    # Bottom and four walls; no top: the cup's inside is open space.
    quads = [(1, 3, 4, 2), (1, 2, 6, 5), (3, 7, 8, 4), (1, 5, 7, 3), (2, 4, 8, 6)]
    lines = [f"v {a} {b} {c}" for a, b, c in corners]
    lines += [f"f {a} {b} {c}\nf {a} {c} {d}" for a, b, c, d in quads]
    (folder / "cup.obj").write_text("\n".join(lines) + "\n")
    return "cup.obj"


@pytest.mark.parametrize("simulator", SIMULATORS)
def test_a_concave_mesh_has_an_inside(
    panda: RobotModel, simulator: str, tmp_path: Path
) -> None:
    """The hand held inside an open cup touches nothing: its hull would hold it."""
    cup = ObjectSpec(
        name="cup",
        shape="mesh",
        file=_cup(tmp_path),
        pose=Pose(position=(0.307, 0, 0.5)),
    )
    with Simulation(
        panda, [cup], panda.home(), folder=tmp_path, simulator=simulator
    ) as sim:
        sim.run_until(0.2)
        assert sim.recording()["contact_force"].max() == 0.0
        np.testing.assert_allclose(sim.q, panda.home(), atol=1e-4)
    # The same cup flattened to 5 cm, its bottom (z 0.5 m) through the fingers.
    tray = ObjectSpec(
        name="tray",
        shape="mesh",
        file="cup.obj",
        scale=(1.0, 1.0, 0.25),
        pose=Pose(position=(0.307, 0, 0.525)),
    )
    with Simulation(
        panda, [tray], panda.home(), folder=tmp_path, simulator=simulator
    ) as sim:
        sim.run_until(0.2)
        assert sim.recording()["wrist_force"].max() > 1.0


def _pressed(
    panda: RobotModel, simulator: str, obj: ObjectSpec
) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] and contact forces [N] of the Panda holding home for 0.4 s."""
    with Simulation(panda, [obj], panda.home(), simulator=simulator) as sim:
        sim.run_until(0.4)
        rec = sim.recording()
    return rec["t"], rec["contact_force"]


@pytest.mark.parametrize("simulator", SIMULATORS)
def test_an_object_that_appears_appears(panda: RobotModel, simulator: str) -> None:
    """A box due at 0.2 s through the hand: no contact before, contact after."""
    box = ObjectSpec(
        name="late",
        shape="box",
        size=(0.1, 0.1, 0.1),
        pose=Pose(position=(0.307, 0.0, 0.50)),
        appear_at=0.2,
    )
    t, force = _pressed(panda, simulator, box)
    assert force[t < 0.2].max() == 0.0  # placed for the step that ends at 0.2 s
    assert force[t > 0.25].min() > 0.0


@pytest.mark.parametrize("simulator", SIMULATORS)
def test_a_moving_object_moves(panda: RobotModel, simulator: str) -> None:
    """A box sliding into the hand from 0.2 s on touches it only once it gets there."""
    box = ObjectSpec(
        name="slider",
        shape="box",
        size=(0.1, 0.1, 0.1),
        pose=Pose(position=(0.307, 0.3, 0.50)),
        motion=ObjectMotion(velocity=(0.0, -2.0, 0.0), start=0.2, stop=0.35),
    )
    t, force = _pressed(panda, simulator, box)
    assert force[t <= 0.25].max() == 0.0  # 10 cm from the hand at 0.25 s
    assert force[t > 0.35].min() > 0.0


@pytest.mark.skipif(
    NO_MUJOCO, reason="needs the mujoco extra: pip install -e '.[mujoco]'"
)
def test_mujoco_places_links_where_pinocchio_does(panda: RobotModel) -> None:
    """Every link (the welded fingers too) where the engine's model puts it at q."""
    from cbp.sim.mujoco.physics import MujocoPhysics

    q = panda.home() + 0.2
    with Simulation(panda, [BOX], q, simulator="mujoco") as sim:
        assert isinstance(sim.physics, MujocoPhysics)
        scene = sim.physics.scene
        data = pin.Data(panda.model)
        pin.framesForwardKinematics(panda.model, data, q)
        assert "panda_leftfinger" in scene.link_bodies
        for name, body in scene.link_bodies.items():
            expected = data.oMf[panda.model.getFrameId(name)]
            np.testing.assert_allclose(
                scene.data.xpos[body], expected.translation, atol=1e-9
            )
            np.testing.assert_allclose(
                scene.data.xmat[body].reshape(3, 3), expected.rotation, atol=1e-9
            )
        np.testing.assert_allclose(
            scene.data.xpos[scene.object_bodies["box"]], BOX.pose.position
        )


@pytest.mark.skipif(
    NO_MUJOCO, reason="needs the mujoco extra: pip install -e '.[mujoco]'"
)
def test_every_engine_in_the_table_has_what_its_simulation_calls() -> None:
    """Each ``module:class`` of SIMULATORS imports and has its protocol's methods."""
    import importlib

    from cbp.sim.physics import SIMULATORS, MobilePhysics, Physics

    protocols = {"fixed": Physics, "mobile": MobilePhysics}
    for _, classes in SIMULATORS.values():
        assert set(classes) == set(protocols)
        for kind, where in classes.items():
            module, name = where.split(":")
            engine = getattr(importlib.import_module(module), name)
            wanted = {m for m in vars(protocols[kind]) if not m.startswith("_")}
            assert wanted <= set(dir(engine)), (where, wanted - set(dir(engine)))


def test_a_missing_mujoco_names_its_extra(
    panda: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without MuJoCo installed, the error names the extra that installs it."""
    monkeypatch.setitem(sys.modules, "mujoco", None)
    for name in [m for m in sys.modules if m.startswith("cbp.sim.mujoco")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.raises(ConfigError, match=r"cbp\[mujoco\]"):
        Simulation(panda, [], panda.home(), simulator="mujoco")


def test_pybullet_names_stay_on_a_pybullet_simulation(panda: RobotModel) -> None:
    """``client`` and ``scene`` are PyBullet's; on MuJoCo they say what to use."""
    with Simulation(panda, [BOX], panda.home()) as sim:
        assert sim.scene.client == sim.client
        assert "box" in sim.scene.object_ids
    if NO_MUJOCO:
        return
    with (
        Simulation(panda, [], panda.home(), simulator="mujoco") as sim,
        pytest.raises(AttributeError, match="runs on mujoco"),
    ):
        _ = sim.client


@pytest.mark.parametrize("simulator", SIMULATORS)
def test_the_youbot_follows_base_and_arm_velocities(simulator: str) -> None:
    """The base goes where the command takes it; the arm tracks its reference."""
    from cbp.sim.mobile import MobileSimulation

    youbot = RobotModel.load("kuka_youbot", base="planar")
    q0 = youbot.home()
    v = np.zeros(youbot.nv)
    v[0], v[2] = 0.3, 0.5  # forward at 0.3 m/s while turning at 0.5 rad/s
    v[3:] = [0.5, -0.3, 0.4, 0.6, -0.8]
    with MobileSimulation(youbot, [], q0, simulator=simulator) as sim:
        sim.command(v)
        errors = []
        for k in range(1, 51):
            sim.run_until(0.02 * k)
            errors.append(np.abs(sim.q[4:] - (q0[4:] + v[3:] * sim.t)).max())
        expected = youbot.integrate(q0, v)  # 1 s at the commanded twist
        np.testing.assert_allclose(sim.q[:4], expected[:4], atol=1e-9)
        assert max(errors[5:]) < 2e-3  # rad, once under way
        sim.command(np.zeros(youbot.nv))
        sim.run_until(1.5)
        np.testing.assert_allclose(sim.q[4:], q0[4:] + v[3:], atol=1e-4)


@pytest.mark.slow
@pytest.mark.parametrize("simulator", SIMULATORS)
def test_cat_reaches_the_free_step_goal_without_contact(simulator: str) -> None:
    """CAT on the free-space step scene reaches at 0 N on either engine."""
    scenario = load_virtual(
        ROOT / "scenarios" / "cat_free_step.yaml",
        {"simulator": simulator, "duration": "2.5"},
    )
    trace = load_executor("cat")(scenario, False)
    metrics = run_metrics(trace, scenario.robot)
    assert metrics["reached"]
    assert metrics["peak_contact_force_n"] == 0.0


#: Three of the paper's scenes, for CI's time: one reached through boards, one
#: that stops short, one among shelves (docs/simulators.md has all eight).
ALIKE = ("boards", "local_minimum", "shelf_retreat")


@pytest.mark.slow
@pytest.mark.skipif(
    NO_MUJOCO, reason="needs the mujoco extra: pip install -e '.[mujoco]'"
)
@pytest.mark.parametrize("scene", ALIKE)
def test_a_paper_scene_ends_alike_on_both_engines(scene: str) -> None:
    """CAT with the declared objects: the same outcome, at 0 N, on the same path."""
    runs = {}
    for simulator in ("pybullet", "mujoco"):
        scenario = load_virtual(
            ROOT / "scenarios" / f"cat_{scene}.yaml", {"simulator": simulator}
        )
        trace = load_executor("cat")(scenario, False)
        runs[simulator] = (trace, run_metrics(trace, scenario.robot))
    (bullet, a), (mujoco, b) = runs["pybullet"], runs["mujoco"]
    assert a["reached"] == b["reached"]
    assert a["peak_contact_force_n"] == b["peak_contact_force_n"] == 0.0
    assert abs(a["final_position_error_m"] - b["final_position_error_m"]) < 1e-4
    n = min(len(bullet.q), len(mujoco.q))
    assert np.abs(bullet.q[:n] - mujoco.q[:n]).max() < 1e-6  # rad; measured 1e-9
