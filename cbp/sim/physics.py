# SPDX-License-Identifier: Apache-2.0
"""The physics engine under a :class:`~cbp.sim.simulation.Simulation`: one part.

A simulation's controller (the trajectory follower, torque controllers,
the recorder) is the same on every engine; what differs is how torques reach
the joints, how a step is taken and how contact is read. :class:`Physics`
says what the controller calls; :data:`SIMULATORS` names the engines, each
found by name (a scenario's ``simulator:``) and imported only when used:

* ``pybullet``: :class:`cbp.sim.bullet_physics.BulletPhysics` (the default);
* ``mujoco``: :class:`cbp.sim.mujoco.physics.MujocoPhysics` (the ``mujoco``
  extra).
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Protocol, get_args

from cbp.errors import ConfigError
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings, SimulatorName

__all__ = [
    "SIMULATORS",
    "Physics",
    "links_beyond",
    "make_physics",
]

#: Engine name -> (module, class, the extra that installs it).
SIMULATORS: dict[str, tuple[str, str, str]] = {
    "pybullet": ("cbp.sim.bullet_physics", "BulletPhysics", ""),
    "mujoco": ("cbp.sim.mujoco.physics", "MujocoPhysics", "mujoco"),
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

    Raises:
        ConfigError: an unknown simulator, or one whose extra is not installed.
    """
    if simulator not in SIMULATORS:
        raise ConfigError(
            f"unknown simulator '{simulator}' (one of {', '.join(SIMULATORS)})",
            "simulator",
        )
    module_name, class_name, extra = SIMULATORS[simulator]
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        if not extra or exc.name != simulator:
            raise
        raise ConfigError(
            f"simulator '{simulator}' needs the '{extra}' extra: "
            f"pip install 'cbp[{extra}]'",
            "simulator",
        ) from None
    physics: Physics = getattr(module, class_name)(
        robot, objects, q0, settings, folder, gui
    )
    return physics


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
