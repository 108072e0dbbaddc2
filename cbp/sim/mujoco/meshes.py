# SPDX-License-Identifier: Apache-2.0
"""A scenario's mesh object as pieces MuJoCo collides: convex, as MuJoCo needs.

MuJoCo collides a mesh as its convex hull. PyBullet takes a mesh object as a
concave triangle mesh, and the collision world keeps it non-convex too
(:meth:`cbp.collision.environment_object.EnvironmentObject.mesh`): a bowl or
an arch has an inside. So a mesh that is not convex becomes one thin prism
per triangle (the triangle and its copy :data:`SHELL` inside, along the
face's normal), each a convex piece: the same surface, with no inside. A
convex mesh stays one piece.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cbp.files import load_mesh
from cbp.robot import FloatArray

__all__ = ["SHELL", "mesh_pieces"]

#: How thick each triangle of a non-convex mesh is made [m].
SHELL = 0.001

#: Triangles smaller than this are left out [m^2] (MuJoCo refuses a piece
#: without volume).
MIN_AREA = 1e-10


def mesh_pieces(path: Path, scale: tuple[float, float, float]) -> list[FloatArray]:
    """The vertices (n, 3) of each convex piece of the mesh file at ``path``.

    Args:
        path: the mesh file (any format trimesh reads).
        scale: its scale along x, y, z.

    Raises:
        ConfigError: the file cannot be read as a mesh (:func:`cbp.files.load_mesh`).
    """
    mesh = load_mesh(path)
    mesh.apply_scale(np.asarray(scale, dtype=float))
    if mesh.is_convex:
        return [np.asarray(mesh.vertices, dtype=float)]
    keep = np.asarray(mesh.area_faces) > MIN_AREA
    triangles = np.asarray(mesh.triangles, dtype=float)[keep]
    inward = SHELL * np.asarray(mesh.face_normals, dtype=float)[keep]
    prisms = np.concatenate([triangles, triangles - inward[:, None, :]], axis=1)
    return list(prisms)
