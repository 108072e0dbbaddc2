# SPDX-License-Identifier: Apache-2.0
"""RobotModel: a pinocchio model, names resolved to indices, limits, Lie algebra."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from cbp.data import is_file
from cbp.errors import (
    ConfigError,
    FrameNotFoundError,
    JointNotFoundError,
    close_matches_hint,
)
from cbp.robot import joints
from cbp.robot.arrays import FloatArray, IndexRows, IntArray
from cbp.robot.description import BaseType, RobotDescription
from cbp.robot.loading import build_model, load_robot_folder, reduced_model

__all__ = ["LIMIT_TOLERANCE", "RobotModel"]

#: How far past a joint limit a home or initial position may lie [rad or m]:
#: a value at the limit, written rounded (robot.yaml keeps 4 decimals), passes.
LIMIT_TOLERANCE = 1e-4


class RobotModel:
    """A kinematic model: pinocchio ``Model`` plus name lookup, limits and Lie algebra.

    Attributes:
        model: the pinocchio model (do not modify it).
        name: the robot's name.
        description: the parsed ``robot.yaml``, when loaded from a folder.
        urdf_path: the URDF file the model came from, when there is one.
        base: how the root is attached: ``fixed``, ``planar`` or ``floating``.
        folder: the robot description folder, when loaded with :meth:`load`.
    """

    def __init__(
        self,
        model: pin.Model,
        *,
        name: str | None = None,
        description: RobotDescription | None = None,
        urdf_path: Path | None = None,
        base: BaseType = "fixed",
    ) -> None:
        """Wrap a pinocchio model; limits and name tables are computed once here."""
        self.model = model
        self.name = name or model.name
        self.description = description
        self.urdf_path = urdf_path
        self.base = base
        self.folder: Path | None = None
        lower, upper = joints.position_limits(model)
        self._lower = lower
        self._upper = upper
        self._joint_ids = {model.names[i]: i for i in range(1, model.njoints)}
        self._frame_ids = {f.name: i for i, f in enumerate(model.frames)}
        velocity = joints.velocity_limits(model)
        accel = np.full(model.nv, 10.0)
        if description is not None:
            for joint, value in description.velocity_limits.items():
                velocity[self.joint_v_slice(joint)] = value
            for joint, value in description.acceleration_limits.items():
                accel[self.joint_v_slice(joint)] = value
        self._velocity = velocity
        self._acceleration = accel
        #: Scalar coordinates with a finite range: what a joint-limit
        #: constraint bounds (configuration and tangent indices).
        self.bounded_q, self.bounded_v = joints.bounded_coordinates(model, lower, upper)
        #: True when every joint has nq == nv (no rotations stored as cos/sin or
        #: quaternions): then q1 ⊖ q0 = q1 - q0 and its Jacobian is the identity.
        self.is_euclidean = model.nq == model.nv
        #: ``support[j, v]`` is 1 where velocity coordinate v moves joint j's body
        #: (v belongs to a joint on the path from the root to j), else 0:
        #: (njoints, nv).
        self.support = joints.support_matrix(model)
        self._identity = np.eye(model.nv)
        self._selections: dict[object, FloatArray] = {}
        for arr in (
            self._lower,
            self._upper,
            self._velocity,
            self._acceleration,
            self._identity,
        ):
            arr.flags.writeable = False

    # ------------------------------------------------------------------ loading

    @classmethod
    def from_urdf(
        cls,
        urdf: str | Path,
        *,
        base: BaseType = "fixed",
        locked_joints: Mapping[str, float] | None = None,
        name: str | None = None,
        description: RobotDescription | None = None,
    ) -> RobotModel:
        """Load a URDF, optionally on a planar or floating base, with joints locked.

        Args:
            urdf: path of the URDF file.
            base: ``fixed`` keeps the URDF root fixed to the world; ``planar`` adds
                a planar joint (x, y, yaw; nq 4, nv 3); ``floating`` adds a free
                flyer (nq 7, nv 6).
            locked_joints: joints to remove, each held at the given position.
            name: robot name (default: the URDF's).
            description: the robot.yaml contents, when loading a robot folder.
        """
        path = Path(urdf)
        model = build_model(path, base)
        if locked_joints:
            model = reduced_model(cls(model, name=name), locked_joints)
        return cls(model, name=name, description=description, urdf_path=path, base=base)

    @classmethod
    def load(
        cls,
        name: str,
        *,
        base: BaseType | None = None,
        relative_to: Path | None = None,
    ) -> RobotModel:
        """Load the robot folder ``name`` (see :func:`~cbp.robot.find_robot_folder`).

        ``base`` defaults to the one robot.yaml names (``fixed`` if none); a
        path ``name`` is relative to ``relative_to`` when given.
        """
        return load_robot_folder(cls, name, base, relative_to)

    # ------------------------------------------------------------------ sizes and names

    @property
    def end_effector(self) -> str:
        """The frame a goal task moves by default.

        robot.yaml's ``end_effector``, else the model's last frame.
        """
        if self.description is not None:
            return self.description.end_effector
        return self.frame_names[-1]

    @property
    def urdf_name(self) -> str:
        """How messages name the URDF: its file name, else the robot's name."""
        if self.urdf_path is not None:
            return self.urdf_path.name
        return f"robot '{self.name}'"

    @property
    def source(self) -> Path | None:
        """The file the robot was described in: its robot.yaml, else its URDF."""
        if self.folder is not None and self.description is not None:
            yaml_file = self.folder / "robot.yaml"
            if is_file(yaml_file):
                return yaml_file
        return self.urdf_path

    @property
    def nq(self) -> int:
        """Number of configuration coordinates."""
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        """Dimension of the tangent space: the number of QP variables."""
        return int(self.model.nv)

    @property
    def joint_names(self) -> list[str]:
        """Names of the model's joints (the universe excluded), in tree order."""
        return list(self._joint_ids)

    def coordinate_names(self, space: Literal["q", "v"] = "q") -> list[str]:
        """One name per configuration (``q``) or velocity (``v``) coordinate.

        A joint with one coordinate lends it its name; a joint with several (a
        planar or floating base) numbers them: ``root_0``, ``root_1``, ...
        """
        return joints.coordinate_names(self.model, space)

    def coordinate_units(self, space: Literal["q", "v"] = "q") -> list[str]:
        """The unit of each coordinate of :meth:`coordinate_names`: ``m`` or ``rad``.

        A prismatic joint's coordinate is in metres, a revolute or continuous
        joint's in radians (a continuous joint's cosine and sine count as
        radians); a planar base's are x, y [m] then its heading, a floating
        base's a position [m] then a rotation.
        """
        return joints.coordinate_units(self.model, space)

    @property
    def frame_names(self) -> list[str]:
        """Names of every frame of the model."""
        return list(self._frame_ids)

    def frame_id(self, name: str) -> int:
        """Return the frame index of ``name``; the error lists close matches."""
        try:
            return self._frame_ids[name]
        except KeyError:
            raise FrameNotFoundError(
                f"no frame '{name}' in robot '{self.name}'"
                + close_matches_hint(name, self._frame_ids)
            ) from None

    def joint_id(self, name: str) -> int:
        """Return the joint index of ``name``; the error lists close matches."""
        try:
            return self._joint_ids[name]
        except KeyError:
            raise JointNotFoundError(
                f"no joint '{name}' in robot '{self.name}'"
                + close_matches_hint(name, self._joint_ids)
            ) from None

    def joint_v_slice(self, name: str) -> slice:
        """Tangent-space indices of joint ``name``."""
        joint = self.model.joints[self.joint_id(name)]
        return slice(joint.idx_v, joint.idx_v + joint.nv)

    def joint_q_slice(self, name: str) -> slice:
        """Configuration indices of joint ``name``."""
        joint = self.model.joints[self.joint_id(name)]
        return slice(joint.idx_q, joint.idx_q + joint.nq)

    def fixed_links(self) -> frozenset[str]:
        """The links of a fixed-base robot that no joint moves (its base).

        No motion changes their distance to an obstacle, so the scenario's
        objects are not checked against them (a floor under the base, a wall
        it is mounted on touch it); the robot's other links still are. Empty
        for a robot whose base moves.
        """
        if self.base != "fixed":
            return frozenset()
        model = self.model
        return frozenset(
            f.name
            for f in model.frames
            if f.parentJoint == 0 and f.type == pin.FrameType.BODY
        )

    def set_joint_position(self, q: FloatArray, name: str, value: float) -> None:
        """Write joint ``name``'s position ``value`` [rad or m] into ``q``.

        A continuous joint keeps its angle as (cos, sin) in two coordinates.

        Raises:
            ConfigError: the joint has more than one degree of freedom (a
                planar or floating base), so one value does not place it.
        """
        joint = self.model.joints[self.joint_id(name)]
        iq = joint.idx_q
        if joint.nq == 1:
            q[iq] = value
        elif joint.nq == 2 and joint.nv == 1:
            q[iq], q[iq + 1] = math.cos(value), math.sin(value)
        else:
            raise ConfigError(
                f"joint {name!r} has {joint.nv} degrees of freedom: one value "
                "does not place it"
            )

    def joint_position(self, q: FloatArray, name: str) -> float:
        """Joint ``name``'s position in ``q`` [rad or m]; a continuous joint's angle."""
        joint = self.model.joints[self.joint_id(name)]
        if joint.nq == 2 and joint.nv == 1:
            return float(np.arctan2(q[joint.idx_q + 1], q[joint.idx_q]))
        return float(q[joint.idx_q])

    def joint_range(self, name: str) -> tuple[float, float, str] | None:
        """(lower, upper, unit) of joint ``name``'s position; None when unbounded.

        Continuous joints, planar and floating bases have no range; the unit is
        ``m`` for a prismatic joint, else ``rad``.
        """
        joint = self.model.joints[self.joint_id(name)]
        if joint.nq != 1 or joint.nv != 1:
            return None
        lower, upper = self._lower[joint.idx_q], self._upper[joint.idx_q]
        if not (np.isfinite(lower) and np.isfinite(upper)):
            return None
        return float(lower), float(upper), self.coordinate_units()[joint.idx_q]

    def out_of_range(self, name: str, value: float) -> str | None:
        """Why ``value`` cannot be joint ``name``'s position, or None when it can.

        A value past a limit by at most :data:`LIMIT_TOLERANCE` is accepted.
        """
        limits = self.joint_range(name)
        if limits is None:
            return None
        lower, upper, unit = limits
        if lower - LIMIT_TOLERANCE <= value <= upper + LIMIT_TOLERANCE:
            return None
        return (
            f"joint '{name}' at {value:g} {unit} is outside its range "
            f"[{lower:.4g}, {upper:.4g}] {unit} ({self.urdf_name})"
        )

    def joint_v_indices(self, names: Sequence[str]) -> IntArray:
        """Tangent-space indices of the joints ``names``, in the order given."""
        idx: list[int] = []
        for name in names:
            sl = self.joint_v_slice(name)
            idx.extend(range(sl.start, sl.stop))
        return np.array(idx, dtype=np.intp)

    def articulated_v_indices(self) -> slice:
        """Tangent-space indices of every joint except a planar or floating root."""
        if self.base == "fixed":
            return slice(0, self.nv)
        return slice(int(self.model.joints[1].nv), self.nv)

    # ------------------------------------------------------------------ limits

    @property
    def lower_limits(self) -> FloatArray:
        """Lower position limits (nq); -inf where unbounded."""
        return self._lower

    @property
    def upper_limits(self) -> FloatArray:
        """Upper position limits (nq); +inf where unbounded."""
        return self._upper

    @property
    def velocity_limits(self) -> FloatArray:
        """Velocity limits (nv) [rad/s or m/s]; +inf where none is known."""
        return self._velocity

    @property
    def acceleration_limits(self) -> FloatArray:
        """Acceleration limits (nv) [rad/s^2 or m/s^2]."""
        return self._acceleration

    def stopping_time(
        self,
        velocity: FloatArray | None = None,
        acceleration: FloatArray | None = None,
    ) -> float:
        """The longest a joint takes to stop from its top speed [s].

        From the robot's limits, or the ``velocity`` and ``acceleration`` limits
        given (an executor's scaled ones); joints without a finite, positive
        pair are left out.
        """
        v = self._velocity if velocity is None else np.asarray(velocity)
        a = self._acceleration if acceleration is None else np.asarray(acceleration)
        known = np.isfinite(v) & np.isfinite(a) & (a > 0)
        return float(np.max(v[known] / a[known])) if known.any() else 0.0

    # ------------------------------------------------------------------ configurations

    def neutral(self) -> FloatArray:
        """The neutral configuration (zeros, identity rotations)."""
        return np.array(pin.neutral(self.model), dtype=float)

    def home(self) -> FloatArray:
        """The home posture of robot.yaml (neutral where a joint is not listed)."""
        q = self.neutral()
        if self.description is not None:
            for joint, value in self.description.home.items():
                self.set_joint_position(q, joint, value)
        return q

    def middle(self) -> FloatArray:
        """Middle of the joint ranges where bounded, neutral elsewhere."""
        q = self.neutral()
        q[self.bounded_q] = 0.5 * (
            self._lower[self.bounded_q] + self._upper[self.bounded_q]
        )
        return q

    def integrate(self, q: FloatArray, dq: FloatArray) -> FloatArray:
        """Return q ⊕ dq: the configuration reached from q by tangent step dq."""
        return np.asarray(pin.integrate(self.model, q, dq), dtype=float)

    def difference(self, q0: FloatArray, q1: FloatArray) -> FloatArray:
        """Return q1 ⊖ q0: the tangent step that takes q0 to q1."""
        if self.is_euclidean:
            return q1 - q0
        return np.asarray(pin.difference(self.model, q0, q1), dtype=float)

    def difference_into(
        self,
        q0: FloatArray,
        q1: FloatArray,
        out: FloatArray,
        rows: IndexRows | None = None,
    ) -> None:
        """Write (q1 ⊖ q0)[rows] into ``out``; no allocation on Euclidean models."""
        if self.is_euclidean:
            if rows is None:
                np.subtract(q1, q0, out=out)
                return
            if isinstance(rows, slice):
                np.subtract(q1[rows], q0[rows], out=out)
                return
        difference = self.difference(q0, q1)
        out[:] = difference if rows is None else difference[rows]

    def difference_jacobian(
        self, q0: FloatArray, q1: FloatArray, rows: IndexRows | None = None
    ) -> FloatArray:
        """Jacobian of (q1 ⊖ q0)[rows] with respect to a tangent perturbation of q1.

        Shape (len(rows), nv), or (nv, nv) for all rows. On Euclidean models it is
        a constant selection of the identity, cached and returned read-only: do not
        modify it.
        """
        if rows is None:
            key: object = None
        elif isinstance(rows, slice):  # slices are unhashable before Python 3.12
            key = (rows.start, rows.stop, rows.step)
        else:
            key = tuple(rows.tolist())
        if self.is_euclidean:
            selection = self._selections.get(key)
            if selection is None:
                selection = np.array(
                    self._identity if rows is None else self._identity[rows]
                )
                selection.flags.writeable = False
                self._selections[key] = selection
            return selection
        J = np.asarray(pin.dDifference(self.model, q0, q1, pin.ArgumentPosition.ARG1))
        return J if rows is None else J[rows]

    def check_configuration(self, q: npt.ArrayLike, what: str = "q") -> FloatArray:
        """Return ``q`` as a float array after checking its size and finiteness."""
        arr = np.asarray(q, dtype=float).reshape(-1)
        if arr.shape != (self.nq,):
            raise ConfigError(
                f"{what} has {arr.size} entries, expected nq = {self.nq} for "
                f"robot '{self.name}'"
            )
        if not np.all(np.isfinite(arr)):
            raise ConfigError(f"{what} is not finite: {arr}")
        return arr

    def random_configuration(
        self, rng: np.random.Generator, *, margin: float = 0.0, base_range: float = 1.0
    ) -> FloatArray:
        """Sample a configuration uniformly inside the limits, shrunk by ``margin``.

        Unbounded coordinates (a mobile base's position) are sampled in
        ±``base_range``; rotations of planar, floating and continuous joints are
        uniform. The draw is fully determined by ``rng``.
        """
        lower = np.where(np.isfinite(self._lower), self._lower + margin, -base_range)
        upper = np.where(np.isfinite(self._upper), self._upper - margin, base_range)
        q = self.neutral()
        joints.sample_joints(self.model, q, lower, upper, rng)
        return q

    def __repr__(self) -> str:
        """Name, base and sizes."""
        return (
            f"RobotModel({self.name!r}, base={self.base!r}, nq={self.nq}, nv={self.nv})"
        )
