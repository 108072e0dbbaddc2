# SPDX-License-Identifier: Apache-2.0
"""Robot models: a URDF loaded through pinocchio, with names resolved to indices.

Configurations ``q`` have ``nq`` entries; velocities and displacements live in the
tangent space and have ``nv`` entries. The two differ for continuous joints (cos, sin),
planar bases (x, y, cos, sin) and floating bases (position + quaternion), which is why
every change of configuration goes through :meth:`RobotModel.integrate` and
:meth:`RobotModel.difference`.
"""

from __future__ import annotations

import math
import os
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt
import pinocchio as pin
import yaml
from yaml.nodes import Node

from cbp.data import data_dir, is_file
from cbp.errors import (
    ConfigError,
    FrameNotFoundError,
    JointNotFoundError,
    RobotNotFoundError,
    close_matches,
)
from cbp.schema import INVALID, Document, value_node
from cbp.urdf_files import missing_meshes

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

#: Rows of a tangent vector: a slice or an array of indices.
IndexRows = slice | IntArray

BaseType = Literal["fixed", "planar", "floating"]

#: How mesh collision elements are turned into convex shapes.
Approximation = Literal["hull", "capsule"]

#: Pinocchio marks an unbounded coordinate with the largest double; treat anything this
#: large as no bound at all.
_UNBOUNDED = 1e300

#: How far past a joint limit a home or initial position may lie [rad or m]:
#: a value at the limit, written rounded (robot.yaml keeps 4 decimals), passes.
LIMIT_TOLERANCE = 1e-4

#: Where robot description folders are looked up, after ``CBP_ROBOT_PATH``:
#: the robots that ship with cbp (:func:`cbp.data.data_dir`).
ROBOTS_DIR = data_dir("robots")


@dataclass(frozen=True, kw_only=True)
class CollisionDescription:
    """The ``collision:`` section of ``robot.yaml``: how the links are checked."""

    padding: float = 0.01
    """Distance added around every link for collision checks [m]."""
    ignore_pairs: list[tuple[str, str]] = field(default_factory=list)
    """Link pairs never checked against each other (beyond adjacent links), e.g.
    pairs that cannot collide; ``cbp robot-pairs NAME`` suggests them by sampling."""
    ignore_links: list[str] = field(default_factory=list)
    """Links left out of every collision check (e.g. fingers meant to touch)."""
    approximation: Approximation = "hull"
    """Mesh elements as their convex ``hull``, or the ``capsule`` around it."""

    def __post_init__(self) -> None:
        """Non-negative padding."""
        if not self.padding >= 0:
            raise ConfigError(f"must be >= 0, got {self.padding}", "padding")


@dataclass(frozen=True, kw_only=True)
class RobotDescription:
    """The schema of a robot folder's ``robot.yaml``."""

    name: str
    """Folder name, also the robot's name in scenarios."""
    urdf: str
    """URDF file, relative to the folder."""
    end_effector: str
    """Frame the default goal task controls."""
    home: dict[str, float]
    """Home posture, by joint name [rad or m]; joints left out take their neutral."""
    base: BaseType = "fixed"
    """The base the robot is built for: ``fixed`` (an arm on a table),
    ``planar`` (an omnidirectional base) or ``floating``."""
    wrist_link: str | None = None
    """First link of the hand: contact forces on it and the links beyond it are
    reported as the wrist force (a wrist force sensor's reading)."""
    locked_joints: dict[str, float] = field(default_factory=dict)
    """Joints removed from the model and held at these positions [rad or m]."""
    velocity_limits: dict[str, float] = field(default_factory=dict)
    """Overrides of the URDF velocity limits, by joint name [rad/s or m/s]."""
    acceleration_limits: dict[str, float] = field(default_factory=dict)
    """Acceleration limits by joint name [rad/s^2 or m/s^2]; default 10 for all."""
    collision: CollisionDescription = field(default_factory=CollisionDescription)
    """Collision settings of the robot's links."""


def find_robot_folder(name: str, relative_to: Path | None = None) -> Path:
    """Return the folder of robot ``name``: a path, or a name under the robot path.

    A path is taken relative to ``relative_to`` (a scenario's folder) when
    given, else to the current folder. The search path is ``CBP_ROBOT_PATH``
    (os.pathsep-separated) then the robots that ship with cbp.

    Raises:
        RobotNotFoundError: saying where it looked, with the nearest robot
            folders' names (beside the scenario, in the current folder, on the
            search path).
    """
    direct = ([relative_to / name] if relative_to is not None else []) + [Path(name)]
    for folder in direct:
        if is_file(folder / "robot.yaml"):
            return folder
    roots = [
        Path(p) for p in os.environ.get("CBP_ROBOT_PATH", "").split(os.pathsep) if p
    ]
    roots.append(ROBOTS_DIR)
    for root in roots:
        if is_file(root / name / "robot.yaml"):
            return root / name
    # Robot folders beside the one named (written as the scenario would name
    # them), then those on the search path (by name).
    parent = Path(name).parent
    local = sorted(
        {
            str(parent / p.parent.name) if str(parent) != "." else p.parent.name
            for folder in direct
            if folder.parent.is_dir()
            for p in folder.parent.glob("*/robot.yaml")
        }
    )
    available = sorted(
        {
            p.parent.name
            for root in roots
            if root.is_dir()
            for p in root.glob("*/robot.yaml")
        }
    )
    hint = close_matches(name, [*local, *available], n=1)
    did_you_mean = f" Did you mean '{hint[0]}'?" if hint else ""
    places: dict[Path, str] = {}
    for folder, label in zip(
        direct,
        ["beside the scenario", "the current folder"][-len(direct) :],
        strict=True,
    ):
        places.setdefault(folder.parent.resolve(), label)
    for root in roots:
        places.setdefault(
            root, "shipped robots" if root == ROBOTS_DIR else "CBP_ROBOT_PATH"
        )
    looked = ", ".join(f"{place} ({label})" for place, label in places.items())
    listing = ", ".join(available) or "none"
    raise RobotNotFoundError(
        f"no robot '{name}': no folder '{Path(name).name}' with a robot.yaml in "
        f"{looked}.{did_you_mean} Robots on the search path: {listing}."
    )


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
        lower = np.array(model.lowerPositionLimit, dtype=float)
        upper = np.array(model.upperPositionLimit, dtype=float)
        lower[lower <= -_UNBOUNDED] = -np.inf
        upper[upper >= _UNBOUNDED] = np.inf
        self._lower = lower
        self._upper = upper
        self._joint_ids = {model.names[i]: i for i in range(1, model.njoints)}
        self._frame_ids = {f.name: i for i, f in enumerate(model.frames)}
        velocity = np.array(model.velocityLimit, dtype=float)
        velocity[(velocity <= 0) | (velocity >= _UNBOUNDED)] = np.inf
        accel = np.full(model.nv, 10.0)
        if description is not None:
            for joint, value in description.velocity_limits.items():
                velocity[self.joint_v_slice(joint)] = value
            for joint, value in description.acceleration_limits.items():
                accel[self.joint_v_slice(joint)] = value
        self._velocity = velocity
        self._acceleration = accel
        # Scalar coordinates with a finite range: what a joint-limit constraint bounds.
        bounded_q: list[int] = []
        bounded_v: list[int] = []
        for j in range(1, model.njoints):
            joint = model.joints[j]
            if joint.nq == 1 and joint.nv == 1:
                iq, iv = joint.idx_q, joint.idx_v
                if np.isfinite(lower[iq]) and np.isfinite(upper[iq]):
                    bounded_q.append(iq)
                    bounded_v.append(iv)
        self.bounded_q: IntArray = np.array(bounded_q, dtype=np.intp)
        self.bounded_v: IntArray = np.array(bounded_v, dtype=np.intp)
        #: True when every joint has nq == nv (no rotations stored as cos/sin or
        #: quaternions): then q1 ⊖ q0 = q1 - q0 and its Jacobian is the identity.
        self.is_euclidean = model.nq == model.nv
        #: ``support[j, v]`` is 1 where velocity coordinate v moves joint j's body
        #: (v belongs to a joint on the path from the root to j), else 0:
        #: (njoints, nv).
        support = np.zeros((model.njoints, model.nv))
        for j in range(model.njoints):
            for k in model.supports[j]:
                if k > 0:
                    joint = model.joints[k]
                    support[j, joint.idx_v : joint.idx_v + joint.nv] = 1.0
        support.flags.writeable = False
        self.support = support
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
        model = _build_model(path, base)
        if locked_joints:
            model = _reduced(model, locked_joints, name)
        return cls(model, name=name, description=description, urdf_path=path, base=base)

    @classmethod
    def load(
        cls,
        name: str,
        *,
        base: BaseType | None = None,
        relative_to: Path | None = None,
    ) -> RobotModel:
        """Load the robot folder ``name`` (see :func:`find_robot_folder`).

        ``base`` defaults to the one robot.yaml names (``fixed`` if none); a
        path ``name`` is relative to ``relative_to`` when given.
        """
        folder = find_robot_folder(name, relative_to)
        doc = Document.from_file(folder / "robot.yaml")
        description = doc.build(RobotDescription, doc.root, "")
        if description is INVALID:
            # The keys that were read are still checked against the URDF, so
            # that one pass reports every problem of the file.
            description = _readable_description(doc)
            if description is None:
                doc.raise_if_problems()
                raise AssertionError("unreachable: the problems were reported")
        base = base or description.base
        path = folder / description.urdf
        try:
            model = _build_model(path, base)
        except ConfigError as exc:
            doc.report(value_node(doc.root, "urdf"), "urdf", exc.message)
            doc.raise_if_problems()
            raise  # unreachable: the problem was reported
        for mesh in missing_meshes(path, [folder]):
            doc.report(
                value_node(doc.root, "urdf"),
                "urdf",
                f"{description.urdf}, line {mesh.line}: {mesh.missing}",
            )
        _check_names(
            doc, description, cls(model, name=description.name, urdf_path=path)
        )
        if description.locked_joints:
            model = _reduced(model, description.locked_joints, description.name)
        robot = cls(
            model,
            name=description.name,
            description=description,
            urdf_path=path,
            base=base,
        )
        robot.folder = folder
        return robot

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
        names = []
        for i, name in enumerate(self.joint_names, start=1):
            joint = self.model.joints[i]
            n = int(joint.nq if space == "q" else joint.nv)
            names += [name] if n == 1 else [f"{name}_{k}" for k in range(n)]
        return names

    def coordinate_units(self, space: Literal["q", "v"] = "q") -> list[str]:
        """The unit of each coordinate of :meth:`coordinate_names`: ``m`` or ``rad``.

        A prismatic joint's coordinate is in metres, a revolute or continuous
        joint's in radians (a continuous joint's cosine and sine count as
        radians); a planar base's are x, y [m] then its heading, a floating
        base's a position [m] then a rotation.
        """
        units: list[str] = []
        for i in range(1, self.model.njoints):
            joint = self.model.joints[i]
            n = int(joint.nq if space == "q" else joint.nv)
            kind = joint.shortname()  # JointModelPX/PY/PZ, JointModelPrismatic...
            if kind == "JointModelPlanar":
                units += ["m", "m"] + ["rad"] * (n - 2)
            elif kind == "JointModelFreeFlyer":
                units += ["m"] * 3 + ["rad"] * (n - 3)
            elif kind.startswith("JointModelPrismatic") or kind[-2:-1] == "P":
                units += ["m"] * n
            else:
                units += ["rad"] * n
        return units

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
                + _matches(name, self._frame_ids)
            ) from None

    def joint_id(self, name: str) -> int:
        """Return the joint index of ``name``; the error lists close matches."""
        try:
            return self._joint_ids[name]
        except KeyError:
            raise JointNotFoundError(
                f"no joint '{name}' in robot '{self.name}'"
                + _matches(name, self._joint_ids)
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
        for j in range(1, self.model.njoints):
            joint = self.model.joints[j]
            iq, nq = joint.idx_q, joint.nq
            kind = joint.shortname()
            if kind == "JointModelFreeFlyer":
                q[iq : iq + 3] = rng.uniform(lower[iq : iq + 3], upper[iq : iq + 3])
                quat = rng.normal(size=4)
                q[iq + 3 : iq + 7] = quat / np.linalg.norm(quat)
            elif kind == "JointModelPlanar":
                q[iq : iq + 2] = rng.uniform(lower[iq : iq + 2], upper[iq : iq + 2])
                angle = rng.uniform(-np.pi, np.pi)
                q[iq + 2 : iq + 4] = (np.cos(angle), np.sin(angle))
            elif nq == 2 and joint.nv == 1:  # continuous joint: (cos, sin)
                angle = rng.uniform(-np.pi, np.pi)
                q[iq : iq + 2] = (np.cos(angle), np.sin(angle))
            else:
                q[iq : iq + nq] = rng.uniform(lower[iq : iq + nq], upper[iq : iq + nq])
        return q

    def __repr__(self) -> str:
        """Name, base and sizes."""
        return (
            f"RobotModel({self.name!r}, base={self.base!r}, nq={self.nq}, nv={self.nv})"
        )


def _matches(name: str, choices: Sequence[str] | Mapping[str, int]) -> str:
    matches = close_matches(name, list(choices))
    return f"; close matches: {', '.join(matches)}" if matches else ""


def compact_rows(rows: IntArray) -> IndexRows:
    """Return ``rows`` as a slice when they are consecutive (cheaper to index with)."""
    if rows.size and np.array_equal(rows, np.arange(rows[0], rows[0] + rows.size)):
        return slice(int(rows[0]), int(rows[0] + rows.size))
    return rows


def rows_count(rows: IndexRows, n: int) -> int:
    """Number of entries ``rows`` selects from a vector of length ``n``."""
    return len(range(n)[rows]) if isinstance(rows, slice) else int(rows.size)


def _build_model(path: Path, base: BaseType) -> pin.Model:
    """The URDF's model on a fixed, planar or floating base."""
    if not is_file(path):
        raise ConfigError(f"URDF file not found: {path}")
    try:
        if base == "fixed":
            return pin.buildModelFromUrdf(str(path))
        if base == "planar":
            return pin.buildModelFromUrdf(str(path), pin.JointModelPlanar())
        if base == "floating":
            return pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(f"cannot load URDF {path}: {exc}") from exc
    raise ConfigError(f"unknown base '{base}'; expected fixed, planar or floating")


def _reduced(
    model: pin.Model, locked_joints: Mapping[str, float], name: str | None
) -> pin.Model:
    """The model without ``locked_joints``, each held at its given position."""
    full = RobotModel(model, name=name)
    ids = [full.joint_id(j) for j in locked_joints]
    q_ref = pin.neutral(model)
    for joint, value in locked_joints.items():
        full.set_joint_position(q_ref, joint, value)
    return pin.buildReducedModel(model, ids, q_ref)


def _key_nodes(root: Node | None, *keys: str) -> dict[str, Node]:
    """Each key of the mapping at ``keys``, by name, for problems at that line."""
    node = value_node(root, *keys)
    if not isinstance(node, yaml.MappingNode):
        return {}
    return {k.value: k for k, _ in node.value if isinstance(k, yaml.ScalarNode)}


def _readable_description(doc: Document) -> RobotDescription | None:
    """robot.yaml's keys that can be read, with defaults for the others.

    None when a required key (``name``, ``urdf``, ``end_effector``, ``home``)
    cannot be read. The problems of the keys left out are already in ``doc``.
    """
    root = doc.root
    if not isinstance(root, yaml.MappingNode):
        return None
    scratch = Document("", doc.path)  # the problems were reported in doc
    fields = typing.get_type_hints(RobotDescription)
    values: dict[str, object] = {}
    for key_node, node in root.value:
        key = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
        if key in fields:
            value = scratch.build(fields[key], node, key)
            if value is not INVALID:
                values[key] = value
    try:
        return RobotDescription(**values)  # type: ignore[arg-type]
    except (TypeError, ConfigError):
        return None


def _check_names(
    doc: Document, description: RobotDescription, full: RobotModel
) -> None:
    """Every joint and link robot.yaml names is in the URDF (problems at their lines).

    ``full`` is the model before locking joints; a joint robot.yaml locks cannot
    have a home, a velocity or an acceleration limit.
    """
    locked = set(description.locked_joints)
    joints, frames = full.joint_names, full.frame_names
    for key, names in (
        ("locked_joints", description.locked_joints),
        ("home", description.home),
        ("velocity_limits", description.velocity_limits),
        ("acceleration_limits", description.acceleration_limits),
    ):
        nodes = _key_nodes(doc.root, key)
        for joint in names:
            if joint not in joints:
                message = (
                    f"no joint '{joint}' in {full.urdf_name}{_matches(joint, joints)}"
                )
            elif key != "locked_joints" and joint in locked:
                message = (
                    f"joint '{joint}' is locked (locked_joints), so it is not in the "
                    "model: remove it here"
                )
            elif key in ("locked_joints", "home") and (
                problem := full.out_of_range(joint, names[joint])
            ):
                message = problem
            else:
                continue
            doc.report(nodes.get(joint), f"{key}.{joint}", message)
    for key in ("end_effector", "wrist_link"):
        frame = getattr(description, key)
        if frame is not None and frame not in frames:
            doc.report(
                value_node(doc.root, key),
                key,
                f"no frame '{frame}' in {full.urdf_name}{_matches(frame, frames)}",
            )
    collision = description.collision
    listed = [
        ("ignore_links", i, link) for i, link in enumerate(collision.ignore_links)
    ]
    listed += [
        ("ignore_pairs", i, link)
        for i, pair in enumerate(collision.ignore_pairs)
        for link in pair
    ]
    for key, i, link in listed:
        if link not in frames:
            node = value_node(doc.root, "collision", key)
            item = node.value[i] if isinstance(node, yaml.SequenceNode) else None
            doc.report(
                item or node,
                f"collision.{key}[{i}]",
                f"no link '{link}' in {full.urdf_name}{_matches(link, frames)}",
            )
    doc.raise_if_problems()
