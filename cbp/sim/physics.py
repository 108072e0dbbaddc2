# SPDX-License-Identifier: Apache-2.0
"""The physics engine under a :class:`~cbp.sim.simulation.Simulation`: one part.

A simulation's controller (the trajectory follower, torque controllers,
the recorder) is the same on every engine; what differs is how torques reach
the joints, how a step is taken and how contact is read. :class:`Physics`
says what the controller calls; :class:`MobilePhysics` what a
:class:`~cbp.sim.mobile.MobileSimulation` calls (a kinematic base, the arm's
joint servos). :data:`SIMULATORS` names the engines, each found by name (a
scenario's ``simulator:``) and imported only when used:

* ``pybullet``: :class:`cbp.sim.bullet_physics.BulletPhysics` and
  :class:`cbp.sim.bullet_physics.BulletMobilePhysics` (the default);
* ``mujoco``: :class:`cbp.sim.mujoco.physics.MujocoPhysics` and
  :class:`cbp.sim.mujoco.mobile.MujocoMobilePhysics` (the ``mujoco`` extra).
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol, get_args

from cbp.errors import ConfigError
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings, SimulatorName

__all__ = [
    "SIMULATORS",
    "MobilePhysics",
    "Physics",
    "links_beyond",
    "make_mobile_physics",
    "make_physics",
]

#: Engine name -> the extra that installs it, and per kind of simulation
#: (``fixed``: :class:`Physics`, ``mobile``: :class:`MobilePhysics`) the
#: class that drives it, as ``module:class``.
SIMULATORS: dict[str, tuple[str, dict[str, str]]] = {
    "pybullet": (
        "",
        {
            "fixed": "cbp.sim.bullet_physics:BulletPhysics",
            "mobile": "cbp.sim.bullet_physics:BulletMobilePhysics",
        },
    ),
    "mujoco": (
        "mujoco",
        {
            "fixed": "cbp.sim.mujoco.physics:MujocoPhysics",
            "mobile": "cbp.sim.mujoco.mobile:MujocoMobilePhysics",
        },
    ),
}
assert set(SIMULATORS) == set(get_args(SimulatorName))


class Physics(Protocol):
    """A robot among the scenario's objects in one physics engine, torque-driven.

    Joint arrays are in the robot model's order (``nv`` scalar joints).
    Built with the robot at its initial configuration and the objects
    present at time 0.
    """

    effort: FloatArray
    """The URDF's effort limit of each joint [N m or N]; 0 where it gives none."""

    def apply(self, tau: Sequence[float]) -> None:
        """Drive the joints with ``tau`` over the next step [N m or N]."""

    def step(self, t: float) -> None:
        """Move the dynamic objects to where they are at ``t`` [s]; take one step."""

    def state(self) -> tuple[FloatArray, FloatArray]:
        """The joints' positions and velocities after the last step."""

    def contact(self) -> tuple[float, float, float]:
        """Contact of the last step between the robot and the scene.

        Returns:
            The sum of normal forces [N] (self-contact and the fixed base's
            links left out), the deepest penetration [m] (>= 0), and the
            sum of normal forces on the hand (``wrist_link`` and beyond) [N].
        """

    def close(self) -> None:
        """Release the engine."""


class MobilePhysics(Protocol):
    """A robot on a kinematic base among the scenario's objects, its arm servoed.

    The arm's joints (the model's joints after the base, in its order) track
    a position reference and a velocity through servos limited by the
    URDF's effort.
    """

    def place_base(self, x: float, y: float, yaw: float) -> None:
        """Put the base at (x, y) [m] turned by ``yaw`` [rad] about the vertical."""

    def drive(self, reference: FloatArray, velocity: FloatArray) -> None:
        """Servo the arm's joints to ``reference`` moving at ``velocity``."""

    def step(self, t: float) -> None:
        """Move the dynamic objects to where they are at ``t`` [s]; take one step."""

    def arm_positions(self) -> FloatArray:
        """The arm's joint positions after the last step."""

    def close(self) -> None:
        """Release the engine."""


def make_physics(
    simulator: str,
    robot: RobotModel,
    objects: list[ObjectSpec],
    q0: FloatArray,
    settings: SimulationSettings,
    folder: Path | None,
    gui: bool,
) -> Physics:
    """The ``simulator`` engine holding ``robot`` at ``q0`` among ``objects``.

    Args:
        simulator: the engine's name (:data:`SIMULATORS`).
        robot: the robot (fixed base).
        objects: the scenario's objects.
        q0: the initial configuration.
        settings: the ``simulation:`` settings.
        folder: where mesh files of objects are resolved from.
        gui: open the engine's window.

    Raises:
        ConfigError: an unknown simulator, or one whose extra is not installed.
    """
    physics: Physics = _engine(simulator, "fixed")(
        robot, objects, q0, settings, folder, gui
    )
    return physics


def make_mobile_physics(
    simulator: str,
    robot: RobotModel,
    objects: list[ObjectSpec],
    q0: FloatArray,
    settings: SimulationSettings,
    folder: Path | None,
    gui: bool,
) -> MobilePhysics:
    """The ``simulator`` engine holding a robot on a kinematic base at ``q0``.

    The arguments are :func:`make_physics`'s (``q0`` in the planar layout).

    Raises:
        ConfigError: an unknown simulator, or one whose extra is not installed.
    """
    physics: MobilePhysics = _engine(simulator, "mobile")(
        robot, objects, q0, settings, folder, gui
    )
    return physics


def _engine(simulator: str, kind: str) -> Any:
    """The class that drives a ``kind`` of simulation on ``simulator``."""
    if simulator not in SIMULATORS:
        raise ConfigError(
            f"unknown: '{simulator}' (one of {', '.join(SIMULATORS)})",
            "simulator",
        )
    extra, classes = SIMULATORS[simulator]
    module_name, class_name = classes[kind].split(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        if not extra or exc.name != simulator:
            raise
        raise ConfigError(
            f"'{simulator}' needs the '{extra}' extra: pip install 'cbp[{extra}]'",
            "simulator",
        ) from None
    return getattr(module, class_name)


def links_beyond(
    robot: RobotModel, parents: Mapping[str, str | None]
) -> frozenset[str]:
    """The robot's ``wrist_link`` and every link below it, by name.

    Args:
        robot: the robot (its description names the wrist link).
        parents: each link's parent link in the engine's tree (None: the root).

    Raises:
        ValueError: the wrist link is not a link of the URDF.
    """
    description = robot.description
    name = description.wrist_link if description is not None else None
    if not name:
        return frozenset()
    if name not in parents:
        raise ValueError(f"wrist_link '{name}' is not a link of the URDF")
    links = {name}
    changed = True
    while changed:
        changed = False
        for link, parent in parents.items():
            if parent in links and link not in links:
                links.add(link)
                changed = True
    return frozenset(links)
