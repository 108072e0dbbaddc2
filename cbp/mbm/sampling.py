# SPDX-License-Identifier: Apache-2.0
"""MotionBenchMaker's scene sampler and queries, with a seeded random stream.

As MotionBenchMaker's ``SceneSampler`` and ``ProblemGenerator`` do (read in
its sources, version f505427):

1. the nominal scene is moved by the problem's ``base_offset`` (premultiplied:
   a move in the base frame);
2. the ``World`` variation's random transform moves every object, in the base
   frame (so its yaw turns the whole scene about the robot's base);
3. every other variation moves each object it names by a transform drawn
   anew for that object, in the object's own frame (post-multiplied);
4. a query's hand pose is the object's pose times the query's offset; the
   tip link (``panda_link8``) goes to that pose times the inverse of
   ``ee_offset``.

A variation's transform: a position offset (``uniform``: each axis within
plus or minus the given value; ``gaussian``: zero-mean with that standard
deviation), and a rotation Rx(roll) Ry(pitch) Rz(yaw), roll and yaw uniform
within their bounds, pitch drawn so that the rotations are uniform (the
arc-cosine rule of Kuffner 2004, as robowflex's ``uniformRPY``).

One difference, on purpose: MotionBenchMaker's code at f505427 tests the
type with ``std::string::compare``, which is 0 on a match, so a variation
typed ``uniform`` is drawn as ``gaussian`` there and the reverse; its README
and this module draw each as its name says.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from cbp.errors import ConfigError
from cbp.mbm.files import Family, ObjectQuery, Primitive, Variation
from cbp.robot import FloatArray

__all__ = ["query_pose", "sample_scene", "variation_transform"]


def _rotation(roll: float, pitch: float, yaw: float) -> FloatArray:
    """Rx(roll) Ry(pitch) Rz(yaw): rotations about the moving x, y and z axes."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return np.asarray(Rx @ Ry @ Rz)


def variation_transform(variation: Variation, rng: np.random.Generator) -> FloatArray:
    """One random transform (4, 4) of ``variation``.

    Raises:
        ConfigError: the variation's type is neither uniform nor gaussian.
    """
    if variation.kind == "uniform":
        offset = rng.uniform(-variation.position, variation.position)
    elif variation.kind == "gaussian":
        offset = rng.normal(0.0, 1.0, 3) * variation.position
    else:
        raise ConfigError(
            f"variation type {variation.kind!r}: choose uniform or gaussian", "type"
        )
    half_pi = 0.5 * np.pi
    b = variation.orientation
    roll = rng.uniform(max(-np.pi, -b[0]), min(np.pi, b[0]))
    low, high = max(-half_pi, -b[1]), min(half_pi, b[1])
    ends = sorted((np.cos(low + half_pi), np.cos(high + half_pi)))
    pitch = np.arccos(rng.uniform(*ends))
    yaw = rng.uniform(max(-np.pi, -b[2]), min(np.pi, b[2]))
    T = np.eye(4)
    T[:3, :3] = _rotation(roll, pitch - half_pi, yaw)
    T[:3, 3] = offset
    return T


def sample_scene(
    family: Family, rng: np.random.Generator
) -> tuple[tuple[Primitive, ...], FloatArray]:
    """The family's objects at one sample of its variations, in the base frame.

    Returns:
        The objects, and the transform that moved the nominal scene as a
        whole (``base_offset`` then the ``World`` variation), (4, 4).
    """
    whole = family.base_offset.copy()
    for variation in family.variations:
        if variation.world:
            whole = variation_transform(variation, rng) @ whole
    poses = {o.name: whole @ o.pose for o in family.objects}
    for variation in family.variations:
        if variation.world:
            continue
        for name in variation.names:
            if name in poses:  # MotionBenchMaker warns and goes on
                poses[name] = poses[name] @ variation_transform(variation, rng)
    objects = tuple(replace(o, pose=poses[o.name]) for o in family.objects)
    return objects, whole


def query_pose(
    query: ObjectQuery, objects: tuple[Primitive, ...], ee_offset: FloatArray
) -> FloatArray:
    """Where the tip link goes for ``query`` among ``objects`` (4, 4), base frame.

    Raises:
        ConfigError: the query names an object the scene does not have.
    """
    poses = {o.name: o.pose for o in objects}
    if query.obj not in poses:
        raise ConfigError(
            f"query {query.name} names {query.obj!r}, not in the scene", "queries"
        )
    return np.asarray(poses[query.obj] @ query.offset @ np.linalg.inv(ee_offset))
