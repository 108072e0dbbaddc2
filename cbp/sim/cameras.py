# SPDX-License-Identifier: Apache-2.0
"""A simulation's depth cameras, whichever engine it runs on.

:func:`depth_cameras` builds the cameras of a scenario's ``perception:``
section for a :class:`~cbp.sim.simulation.Simulation`: on PyBullet
:class:`~cbp.sim.camera.DepthCamera` (the ray cast or the tiny renderer, as
each camera's ``renderer`` says; one ray caster for all, so meshes are read
once), on MuJoCo :class:`~cbp.sim.mujoco.camera.MujocoDepthCamera` (the ray cast
of MuJoCo's geoms, or MuJoCo's OpenGL renderer with one context per image
size). Their frames are the same
record with the same matrices, so what reads them (the map) does not know
which engine rendered them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from cbp.perception.spec import CameraSpec
from cbp.robot import RobotModel
from cbp.sim.camera import DepthCamera, SimulatedCamera
from cbp.sim.physics import SIMULATORS
from cbp.sim.simulation import Simulation

__all__ = ["CAMERAS", "depth_cameras"]

#: ``(simulation, specs, robot) -> cameras``: one builder per engine.
CameraBuilder = Callable[
    [Simulation, Sequence[CameraSpec], RobotModel | None], list[SimulatedCamera]
]


def _pybullet(
    sim: Simulation, specs: Sequence[CameraSpec], robot: RobotModel | None
) -> list[SimulatedCamera]:
    """PyBullet's cameras, sharing one ray caster."""
    from cbp.sim.raycast import RayCaster

    caster = RayCaster(sim.client)
    return [DepthCamera(sim.client, spec, robot, caster) for spec in specs]


def _mujoco(
    sim: Simulation, specs: Sequence[CameraSpec], robot: RobotModel | None
) -> list[SimulatedCamera]:
    """MuJoCo's cameras, sharing one ray caster and one renderer per image size."""
    from cbp.sim.mujoco.camera import MujocoDepthCamera, Renderers
    from cbp.sim.mujoco.physics import MujocoPhysics
    from cbp.sim.mujoco.raycast import MujocoRayCaster

    physics = sim.physics
    assert isinstance(physics, MujocoPhysics)
    model, data = physics.model, physics.data
    casts = any(spec.renderer == "raycast" for spec in specs)
    caster = MujocoRayCaster(model, data) if casts else None
    renderers = Renderers(model)  # no OpenGL context until a camera renders
    return [
        MujocoDepthCamera(model, data, spec, robot, renderers, caster) for spec in specs
    ]


#: The cameras' builder of each engine (:data:`cbp.sim.physics.SIMULATORS`).
CAMERAS: dict[str, CameraBuilder] = {"pybullet": _pybullet, "mujoco": _mujoco}
assert set(CAMERAS) == set(SIMULATORS)


def depth_cameras(
    sim: Simulation, specs: Sequence[CameraSpec], robot: RobotModel | None = None
) -> list[SimulatedCamera]:
    """The depth cameras ``specs`` of ``sim``, in their order.

    Args:
        sim: the simulation they render.
        specs: the cameras (``perception.all_cameras``).
        robot: the robot that mounted cameras' ``parent`` frames belong to.

    Raises:
        ConfigError: a camera's mount unknown, or its renderer not the
            engine's.
    """
    return CAMERAS[sim.simulator](sim, specs, robot)
