# SPDX-License-Identifier: Apache-2.0
"""PyBullet simulation: scene, simulated robot, joint trajectories.

The scene is built from a scenario's declarations (:mod:`cbp.sim.scene`); the
simulated robot has a trajectory follower and a torque interface
(:mod:`cbp.sim.simulation`); trajectories are quintic splines
(:mod:`cbp.sim.trajectory`).

Submodules are imported on use, so that loading a scenario does not load PyBullet.
"""
