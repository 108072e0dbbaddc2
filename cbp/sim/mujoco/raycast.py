# SPDX-License-Identifier: Apache-2.0
"""Depth images of a MuJoCo scene by the compiled ray cast: no OpenGL.

:class:`MujocoRayCaster` reads a MuJoCo model's geoms once (planes, boxes
and meshes as triangles; spheres, cylinders and capsules as the true surfaces) and, at
each capture, their placements from the data (``geom_xpos``, ``geom_xmat``,
brought up to the joints' positions). The pass and its caches are
:class:`~cbp.sim.shape_caster.ShapeCaster`'s, the same as PyBullet's ray
cast: for the same scene the two give the same image.
"""

from __future__ import annotations

import mujoco
import numpy as np

from cbp.robot import FloatArray
from cbp.sim.ray_kernels import CAPSULE, CYLINDER, SPHERE
from cbp.sim.shape_caster import CastShape, ShapeCaster, box_triangles

__all__ = ["DEFAULT_GEOM_GROUPS", "INFINITE_PLANE", "MujocoRayCaster"]

DEFAULT_GEOM_GROUPS = (0, 1, 2)
"""The geom groups a camera draws (MuJoCo's visible groups by default)."""

INFINITE_PLANE = 1e3
"""Half the side of the square an infinite plane is drawn as [m]."""

_ANALYTIC = {
    int(mujoco.mjtGeom.mjGEOM_SPHERE): SPHERE,
    int(mujoco.mjtGeom.mjGEOM_CYLINDER): CYLINDER,
    int(mujoco.mjtGeom.mjGEOM_CAPSULE): CAPSULE,
}


class MujocoRayCaster(ShapeCaster):
    """Depth images of a MuJoCo model's geoms, by a compiled ray cast.

    Args:
        model: the model (its geoms are read once: a compiled model is fixed).
        data: its data (where the geoms are at each capture).
        geom_groups: the geom groups drawn.

    Raises:
        ValueError: a geom of a type the cast does not draw (ellipsoids,
            height fields), named.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        geom_groups: tuple[int, ...] = DEFAULT_GEOM_GROUPS,
    ) -> None:
        """Read the geoms of the chosen groups."""
        super().__init__()
        self.model = model
        self.data = data
        self._geoms = np.array(
            [g for g in range(model.ngeom) if model.geom_group[g] in geom_groups],
            dtype=np.intp,
        )
        self._use([self._shape(int(g)) for g in self._geoms])

    def _shape(self, g: int) -> CastShape:
        """Geom ``g``'s surface in its frame."""
        m = self.model
        kind, size = int(m.geom_type[g]), m.geom_size[g]
        if kind == mujoco.mjtGeom.mjGEOM_BOX:
            return CastShape(box_triangles(2.0 * size))
        if kind == mujoco.mjtGeom.mjGEOM_PLANE:  # a box without height
            half = [size[k] if size[k] > 0 else INFINITE_PLANE for k in (0, 1)]
            return CastShape(box_triangles([2.0 * half[0], 2.0 * half[1], 0.0]))
        if kind in _ANALYTIC:
            half_length = 0.0 if kind == mujoco.mjtGeom.mjGEOM_SPHERE else size[1]
            return CastShape(None, _ANALYTIC[kind], float(size[0]), float(half_length))
        if kind == mujoco.mjtGeom.mjGEOM_MESH:
            mesh = m.geom_dataid[g]
            first, count = m.mesh_vertadr[mesh], m.mesh_vertnum[mesh]
            vertices = np.asarray(m.mesh_vert[first : first + count], dtype=float)
            first, count = m.mesh_faceadr[mesh], m.mesh_facenum[mesh]
            faces = np.asarray(m.mesh_face[first : first + count])
            return CastShape(np.ascontiguousarray(vertices[faces]))
        name = m.geom(g).name or f"#{g}"
        raise ValueError(
            f"geom {name} (body '{m.body(m.geom_bodyid[g]).name}'): type "
            f"{mujoco.mjtGeom(kind).name} cannot be ray cast (planes, boxes, "
            "spheres, cylinders, capsules and meshes can)"
        )

    def _placements(self) -> FloatArray:
        """Each geom's frame in the world now (G, 4, 4)."""
        mujoco.mj_kinematics(self.model, self.data)
        out = np.zeros((len(self._geoms), 4, 4))
        out[:, :3, :3] = self.data.geom_xmat[self._geoms].reshape(-1, 3, 3)
        out[:, :3, 3] = self.data.geom_xpos[self._geoms]
        out[:, 3, 3] = 1.0
        return out
