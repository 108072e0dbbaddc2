# SPDX-License-Identifier: Apache-2.0
"""``type: recorded``: a goal file of timestamped poses, replayed.

A recorded goal is a CSV table of poses (``t,x,y,z,qx,qy,qz,qw``: time [s],
position [m], unit quaternion), so that an operator's session is recorded once
and replayed to every method, as the CAT paper did. :func:`write_recorded`
writes one from any stream. Every cell is checked when the file is read (a
number, finite, times increasing, a unit quaternion), and each problem is
named by its row and column: a file that loads replays a pose at every sample.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError, DataFileError
from cbp.files import MAX_TABLE_BYTES, read_text
from cbp.goals.base import GoalSpec, GoalStream, PoseTrack
from cbp.robot import FloatArray
from cbp.schema import MAX_MAGNITUDE

__all__ = [
    "MAX_LISTED",
    "QUATERNION_TOLERANCE",
    "RECORDED_COLUMNS",
    "RecordedGoal",
    "RecordedGoalSpec",
    "read_recorded",
    "recorded_goal_overrides",
    "write_recorded",
]

#: Header of a recorded goal file: time [s], position [m], quaternion (x, y, z, w).
RECORDED_COLUMNS = ("t", "x", "y", "z", "qx", "qy", "qz", "qw")
#: How far a quaternion's norm may be from 1: four decimals written by hand
#: (0.7071 for 1/sqrt(2)) are within it, a zero or a doubled one is not.
QUATERNION_TOLERANCE = 1e-3
#: Most problems of one file listed (a file of a million bad rows says how many).
MAX_LISTED = 20


@dataclass(frozen=True, kw_only=True)
class RecordedGoalSpec(GoalSpec):
    """``type: recorded``: a goal file of poses, interpolated like keyframes.

    ``cbp teleop`` records one for each session, and ``cbp compare --goal``
    replays one to every method.
    """

    type: str = "recorded"
    file: str
    """CSV file (columns t,x,y,z,qx,qy,qz,qw), relative to the scenario file."""


class RecordedGoal(GoalStream):
    """Samples a ``recorded`` section: the file's poses, interpolated.

    Args:
        spec: the section.
        folder: where the file is resolved from (default: the working folder).

    Raises:
        DataFileError: the file cannot be read, or a cell is not what its
            column takes (each problem by row and column; location ``file``).
    """

    type_name = "recorded"
    Spec = RecordedGoalSpec

    def __init__(self, spec: RecordedGoalSpec, folder: Path | None = None) -> None:
        """Read and check the file once."""
        super().__init__(spec, folder)
        self.track = read_recorded((folder or Path.cwd()) / spec.file)

    @property
    def end_time(self) -> float:
        """Time of the last sample [s]."""
        return self.track.times[-1]

    def sample(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Goal position (3,) [m] and rotation (3, 3) at time ``t`` [s], world frame."""
        return self.track.at(t)


def read_recorded(path: Path) -> PoseTrack:
    """The poses of the goal file at ``path``, every cell checked.

    Rows are numbered as the file's lines (the header is row 1), columns from 1.

    Raises:
        DataFileError: every problem (at most :data:`MAX_LISTED` listed),
            located ``file``.
    """
    try:
        text = read_text(path, "recorded goal", MAX_TABLE_BYTES)
        reader = csv.reader(io.StringIO(text, newline=""))
        header = next(reader, [])
    except ConfigError as exc:
        raise DataFileError(str(path), [exc.message], "file") from None
    except csv.Error as exc:
        raise DataFileError(str(path), [f"not a CSV table: {exc}"], "file") from None
    if tuple(c.strip() for c in header) != RECORDED_COLUMNS:
        raise DataFileError(
            str(path),
            [f"row 1: the header must be {','.join(RECORDED_COLUMNS)}"],
            "file",
        )
    problems: list[str] = []
    times: list[float] = []
    positions: list[FloatArray] = []
    rotations: list[FloatArray] = []
    try:
        for row in reader:
            line = reader.line_num
            if not any(cell.strip() for cell in row):
                continue  # a blank line
            values, said = _row_values(row, line)
            if not said and times and values[0] <= times[-1]:
                said = [
                    f"row {line}, column 1 (t): times must increase; "
                    f"{values[0]:g} follows {times[-1]:g}"
                ]
            if not said:
                rotation, said = _rotation(values[4:], line)
            if said:
                problems += said
                continue
            times.append(values[0])
            positions.append(np.array(values[1:4]))
            rotations.append(rotation)
    except csv.Error as exc:
        problems.append(f"row {reader.line_num}: not a CSV row: {exc}")
    if not times and not problems:
        problems.append("no samples after the header")
    if problems:
        listed = problems[:MAX_LISTED]
        if len(problems) > MAX_LISTED:
            listed.append(f"and {len(problems) - MAX_LISTED} more problems")
        raise DataFileError(str(path), listed, "file")
    return PoseTrack(times, positions, rotations)


def _row_values(row: list[str], line: int) -> tuple[list[float], list[str]]:
    """A row's numbers, and what is wrong with its cells."""
    if len(row) != len(RECORDED_COLUMNS):
        return [], [
            f"row {line}: expected {len(RECORDED_COLUMNS)} values, got {len(row)}"
        ]
    values: list[float] = []
    said: list[str] = []
    for column, (name, cell) in enumerate(zip(RECORDED_COLUMNS, row, strict=True), 1):
        where = f"row {line}, column {column} ({name})"
        try:
            value = float(cell)
        except ValueError:
            said.append(f"{where}: cannot read {cell.strip()[:40]!r} as a number")
            continue
        if not (math.isfinite(value) and abs(value) <= MAX_MAGNITUDE):
            said.append(
                f"{where}: expected a finite number of magnitude at most "
                f"{MAX_MAGNITUDE:g}, got {cell.strip()[:40]}"
            )
        values.append(value)
    return values, said


def _rotation(quaternion: list[float], line: int) -> tuple[FloatArray, list[str]]:
    """The rotation of a quaternion (x, y, z, w) of norm 1, or what is wrong."""
    norm = math.sqrt(sum(v * v for v in quaternion))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        written = ", ".join(f"{v:g}" for v in quaternion)
        return np.eye(3), [
            f"row {line}, columns 5-8 (qx, qy, qz, qw): the quaternion ({written}) "
            f"has norm {norm:.4g}, expected 1 (a rotation; within "
            f"{QUATERNION_TOLERANCE:g})"
        ]
    x, y, z, w = (v / norm for v in quaternion)
    return np.asarray(pin.Quaternion(w, x, y, z).matrix()), []


def recorded_goal_overrides(path: Path, settle: float = 2.0) -> dict[str, str]:
    """Scenario overrides that replace the goal with the recording at ``path``.

    The run lasts until the recording's last sample and ``settle`` seconds more
    (``cbp compare --goal``: a teleoperation session replayed to every method).

    Raises:
        DataFileError: the file cannot be read as a recorded goal.
    """
    path = Path(path).resolve()
    track = read_recorded(path)
    goal = {"type": "recorded", "file": str(path)}
    return {"goal": json.dumps(goal), "duration": f"{track.times[-1] + settle:.6f}"}


def write_recorded(
    path: Path, times: Sequence[float], positions: FloatArray, rotations: FloatArray
) -> None:
    """Write poses (positions (N, 3), rotations (N, 3, 3)) as a recorded goal file."""
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(RECORDED_COLUMNS)
        for t, p, R in zip(times, positions, rotations, strict=True):
            q = pin.Quaternion(np.asarray(R))
            writer.writerow(
                [f"{t:.6f}", *(f"{v:.6f}" for v in p)]
                + [f"{v:.8f}" for v in (q.x, q.y, q.z, q.w)]
            )
