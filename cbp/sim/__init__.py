# SPDX-License-Identifier: Apache-2.0
"""Simulation: scene, simulated robot, joint trajectories, on PyBullet or MuJoCo.

The scene is built from a scenario's declarations (:mod:`cbp.sim.scene`,
:mod:`cbp.sim.mujoco`); the simulated robot has a trajectory follower and a
torque interface (:mod:`cbp.sim.simulation`) over a physics engine
(:mod:`cbp.sim.physics`); trajectories are quintic splines
(:mod:`cbp.sim.trajectory`).

Submodules are imported on use, so that loading a scenario loads no simulator.
"""
