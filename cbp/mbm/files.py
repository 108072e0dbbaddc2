# SPDX-License-Identifier: Apache-2.0
"""MotionBenchMaker's configuration files, read into plain records.

A MotionBenchMaker problem family is a problem file
(``configs/problems/<family>_<robot>.yaml``) naming a scene (collision
objects with box and cylinder primitives), a variation file, a query file
and a sensor file, plus the robot's base and end-effector offsets. Paths in
them are ``package://motion_bench_maker/...``; they are resolved against the
root folder of a MotionBenchMaker checkout (the folder holding ``configs/``).

Conventions of the files (MotionBenchMaker and MoveIt's): positions in
metres, orientations as quaternions ``[x, y, z, w]``, a cylinder's
``dimensions`` as ``[height, radius]``, variation orientations as bounds on
roll, pitch and yaw [rad].
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import yaml

from cbp.errors import ConfigError
from cbp.robot import FloatArray

__all__ = [
    "PACKAGE",
    "Family",
    "ObjectQuery",
    "Primitive",
    "Sensors",
    "Variation",
    "family_names",
    "read_family",
    "transform",
]

#: How the files name the package root.
PACKAGE = "package://motion_bench_maker/"


def transform(position: Any, orientation: Any = (0.0, 0.0, 0.0, 1.0)) -> FloatArray:
    """A 4x4 homogeneous transform from a position and a quaternion [x, y, z, w]."""
    x, y, z, w = (float(v) for v in orientation)
    T = np.eye(4)
    T[:3, :3] = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
    T[:3, 3] = [float(v) for v in position]
    return T


@dataclass(frozen=True)
class Primitive:
    """One collision object of a scene: a box or a cylinder at a pose.

    Attributes:
        name: the object's id.
        shape: ``box`` or ``cylinder``.
        dimensions: box (x, y, z) edges; cylinder (height, radius) [m].
        pose: its pose in the robot's base frame (4, 4).
    """

    name: str
    shape: str
    dimensions: tuple[float, ...]
    pose: FloatArray


@dataclass(frozen=True)
class Variation:
    """A random perturbation of some objects' poses (or of the whole scene).

    Attributes:
        names: the objects it moves; ``["World"]``: every object, in the base
            frame (otherwise each object in its own frame, drawn anew for each).
        position: ``uniform``: half-widths of the offsets; ``gaussian``: their
            standard deviations [m].
        orientation: half-widths of roll, pitch and yaw [rad].
        kind: ``uniform`` or ``gaussian``.
    """

    names: tuple[str, ...]
    position: FloatArray
    orientation: FloatArray
    kind: str

    @property
    def world(self) -> bool:
        """Whether it moves the whole scene."""
        return "World" in self.names


@dataclass(frozen=True)
class ObjectQuery:
    """A hand pose given relative to a named object.

    Attributes:
        obj: the object's name.
        tag: the query's tag (``Front``).
        offset: the pose in the object's frame (4, 4).
        position_tolerance: the tolerance box's edges [m] (recorded, not used:
            problems are made for the offset pose itself).
    """

    obj: str
    tag: str
    offset: FloatArray
    position_tolerance: tuple[float, ...]

    @property
    def name(self) -> str:
        """As MotionBenchMaker names it: object, underscore, tag."""
        return f"{self.obj}_{self.tag}"


@dataclass(frozen=True)
class Sensors:
    """Where MotionBenchMaker puts its cameras, and their intrinsics.

    Every camera point looks at every look point: camera ``i, j`` sits at
    ``cam_points[j]`` (base frame) and looks at ``look_objects[i]``'s offset
    in that object's frame.

    Attributes:
        look_objects: (object name, position in its frame) pairs.
        cam_points: camera positions in the base frame [m].
        focal_length: the focal length [px] (x and y are equal in the files).
        width: image width [px].
        height: image height [px].
        near: the near plane [m].
        far: the far plane [m].
        resolution: the octomap's cell size [m].
    """

    look_objects: tuple[tuple[str, tuple[float, float, float]], ...]
    cam_points: tuple[tuple[float, float, float], ...]
    focal_length: float
    width: int
    height: int
    near: float
    far: float
    resolution: float

    @property
    def fov_deg(self) -> float:
        """The vertical field of view [deg]."""
        return float(np.rad2deg(2.0 * np.arctan(0.5 * self.height / self.focal_length)))


@dataclass(frozen=True)
class Family:
    """A problem family: scene, variations, queries, sensors and offsets.

    Attributes:
        name: the family (``bookshelf_small``).
        objects: the nominal scene's objects.
        variations: the variation file's entries, in order.
        goal_queries: hand poses a problem ends at, sorted by name.
        start_queries: hand poses a problem starts at (none: the robot
            file's start state).
        start_state: the robot file's joint positions by name [rad].
        base_offset: moves the nominal scene into the base frame (4, 4).
        ee_offset: the query frame in the tip link's frame (4, 4).
        sensors: the sensor file.
    """

    name: str
    objects: tuple[Primitive, ...]
    variations: tuple[Variation, ...]
    goal_queries: tuple[ObjectQuery, ...]
    start_queries: tuple[ObjectQuery, ...]
    start_state: dict[str, float]
    base_offset: FloatArray
    ee_offset: FloatArray
    sensors: Sensors


def _load(path: Path) -> Any:
    if not path.is_file():
        raise ConfigError(f"no MotionBenchMaker file {path}", "motion_bench_maker")
    return yaml.safe_load(path.read_text())


def _resolve(root: Path, reference: str) -> Path:
    """A ``package://motion_bench_maker/...`` reference as a path under ``root``."""
    if not reference.startswith(PACKAGE):
        raise ConfigError(
            f"expected a path starting {PACKAGE}, got {reference!r}",
            "motion_bench_maker",
        )
    return root / reference.removeprefix(PACKAGE)


def family_names(root: Path, robot: str = "panda") -> list[str]:
    """The problem families ``root`` has for ``robot``, sorted."""
    suffix = f"_{robot}"
    folder = root / "configs" / "problems"
    return sorted(p.stem.removesuffix(suffix) for p in folder.glob(f"*{suffix}.yaml"))


def _primitives(document: Any) -> tuple[Primitive, ...]:
    out = []
    for entry in document["world"]["collision_objects"]:
        (primitive,) = entry["primitives"]
        (pose,) = entry["primitive_poses"]
        shape = str(primitive["type"])
        if shape not in ("box", "cylinder"):
            raise ConfigError(f"{entry['id']}: {shape} is not a box or a cylinder")
        out.append(
            Primitive(
                name=str(entry["id"]),
                shape=shape,
                dimensions=tuple(float(v) for v in primitive["dimensions"]),
                pose=transform(pose["position"], pose["orientation"]),
            )
        )
    return tuple(out)


def _queries(entries: Any) -> tuple[ObjectQuery, ...]:
    out = []
    for entry in entries or []:
        offset = entry["offset"]
        for name in entry["objects"]:
            out.append(
                ObjectQuery(
                    obj=str(name),
                    tag=str(entry["tag"]),
                    offset=transform(offset["position"], offset["orientation"]),
                    position_tolerance=tuple(float(v) for v in offset["position_tol"]),
                )
            )
    return tuple(sorted(out, key=lambda q: q.name))


def _sensors(root: Path, document: Any) -> Sensors:
    camera = _load(_resolve(root, document["camera_config"]))
    fx, fy = float(camera["focal_length_x"]), float(camera["focal_length_y"])
    if fx != fy:
        raise ConfigError(f"focal lengths differ ({fx}, {fy})", "camera_config")
    return Sensors(
        look_objects=tuple(
            (str(e["name"]), tuple(float(v) for v in e["position"]))  # type: ignore[misc]
            for e in document["look_objects"]
        ),
        cam_points=tuple(
            tuple(float(v) for v in p)  # type: ignore[misc]
            for p in document["cam_points"]
        ),
        focal_length=fx,
        width=int(camera["width"]),
        height=int(camera["height"]),
        near=float(camera["z_near"]),
        far=float(camera["z_far"]),
        resolution=float(document["resolution"]),
    )


def read_family(root: Path, name: str, robot: str = "panda") -> Family:
    """Read problem family ``name`` for ``robot`` from the checkout at ``root``.

    Raises:
        ConfigError: a file is missing or holds what this reader does not
            know (a mesh scene, several end effectors), naming the family
            choices when ``name`` is not one.
    """
    path = root / "configs" / "problems" / f"{name}_{robot}.yaml"
    if not path.is_file():
        choices = ", ".join(family_names(root, robot)) or "none"
        raise ConfigError(
            f"no family {name!r} for {robot} under {root} (choices: {choices})",
            "motion_bench_maker",
        )
    problem = _load(path)
    if isinstance(problem["ee_offset"], list):
        raise ConfigError(f"{name}: several end effectors are not supported")
    if not str(problem["scene"]).endswith(".yaml"):
        raise ConfigError(f"{name}: only scenes of primitives (YAML) are supported")
    robot_file = _load(_resolve(root, problem["robot_description"]))
    joints = robot_file["robot_state"]["joint_state"]
    queries = _load(_resolve(root, problem["queries"]))
    base, ee = problem["base_offset"], problem["ee_offset"]
    return Family(
        name=name,
        objects=_primitives(_load(_resolve(root, problem["scene"]))),
        variations=tuple(
            Variation(
                names=tuple(str(n) for n in v["names"]),
                position=np.array(v["position"], dtype=float),
                orientation=np.array(v["orientation"], dtype=float),
                kind=str(v["type"]),
            )
            for v in _load(_resolve(root, problem["variation"]))
        ),
        goal_queries=_queries(queries.get("goal_queries")),
        start_queries=_queries(queries.get("start_queries")),
        start_state={
            str(k): float(v)
            for k, v in zip(joints["name"], joints["position"], strict=True)
        },
        base_offset=transform(base["position"], base["orientation"]),
        ee_offset=transform(ee["position"], ee["orientation"]),
        sensors=_sensors(root, _load(_resolve(root, problem["sensors"]))),
    )
