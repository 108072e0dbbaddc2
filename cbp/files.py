# SPDX-License-Identifier: Apache-2.0
"""Reading the files a scenario names, with limits and errors a user can act on.

Every file ``cbp`` reads on a user's behalf (scenarios and their includes,
recorded goals, meshes, robot descriptions) goes through :func:`check_file`:
it must be a regular file (not a folder, a device such as ``/dev/zero``, or a
pipe) of at most a given size. :func:`read_text` then decodes it as UTF-8 and
names the line and column of the first byte that is not.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import secrets
import shutil
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from cbp.errors import ConfigError

if TYPE_CHECKING:
    import trimesh

__all__ = [
    "MAX_MESH_BYTES",
    "MAX_TABLE_BYTES",
    "MAX_YAML_BYTES",
    "OUTPUT_MARKERS",
    "OutputClaim",
    "check_file",
    "check_folder_name",
    "check_output_folder",
    "claim_new_output_folder",
    "claim_output_folder",
    "load_mesh",
    "read_text",
]

#: A folder holding one of these is an earlier output that may be replaced.
OUTPUT_MARKERS = ("metrics.json", "report.md")

#: Longest name that becomes a folder name (a scenario's or a sweep's).
MAX_NAME_LENGTH = 100

#: Largest scenario, include or robot description file [bytes].
MAX_YAML_BYTES = 4 << 20
#: Largest recorded goal file [bytes] (about 30 h of a 30 Hz stream).
MAX_TABLE_BYTES = 256 << 20
#: Largest mesh file [bytes].
MAX_MESH_BYTES = 256 << 20


def check_file(path: Path, what: str, limit: int) -> int:
    """Check that ``path`` is a readable regular file of at most ``limit`` bytes.

    Args:
        path: the file.
        what: what it is, for the message ("recorded goal", "mesh").
        limit: largest size accepted [bytes].

    Returns:
        Its size [bytes].

    Raises:
        ConfigError: missing, not a regular file, or too large.
    """
    try:
        info = path.stat()
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the name
        reason = getattr(exc, "strerror", None) or exc
        raise ConfigError(f"cannot read {what} {str(path)!r}: {reason}") from None
    if not stat.S_ISREG(info.st_mode):
        kind = "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file"
        raise ConfigError(f"{what} {path} is {kind}")
    if info.st_size > limit:
        raise ConfigError(
            f"{what} {path} is {info.st_size / 1e6:.1f} MB, more than the "
            f"{limit / 1e6:.0f} MB accepted"
        )
    return info.st_size


def read_text(path: Path, what: str, limit: int = MAX_YAML_BYTES) -> str:
    """The text of ``path``, checked by :func:`check_file` and decoded as UTF-8.

    Raises:
        ConfigError: unreadable, not a regular file, too large, or not UTF-8 (the
            message gives the line and column of the first bad byte).
    """
    check_file(path, what, limit)
    try:
        data = path.read_bytes()[: limit + 1]
    except OSError as exc:
        raise ConfigError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if len(data) > limit:  # it grew since stat
        raise ConfigError(f"{what} {path} is larger than {limit / 1e6:.0f} MB")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        before = data[: exc.start]
        line = before.count(b"\n") + 1
        column = exc.start - (before.rfind(b"\n") + 1) + 1
        raise ConfigError(
            f"{what} {path} is not UTF-8 text: byte 0x{data[exc.start]:02x} at "
            f"line {line}, column {column}"
        ) from None


def load_mesh(path: Path, what: str = "mesh") -> trimesh.Trimesh:
    """A triangle mesh file (any format trimesh reads) with at least one face.

    Raises:
        ConfigError: not a regular file, too large, a format trimesh does not
            read, no triangles, or coordinates that are not finite.
    """
    import trimesh

    check_file(path, what, MAX_MESH_BYTES)
    try:
        mesh = trimesh.load(str(path), force="mesh")
    except Exception as exc:  # trimesh raises many types for files it cannot read
        reason = str(exc).split("\n")[0] or type(exc).__name__
        raise ConfigError(f"cannot read {what} {path}: {reason}") from None
    faces = getattr(mesh, "faces", None)
    if faces is None or len(faces) == 0:
        raise ConfigError(f"{what} {path} holds no triangles")
    if not np.all(np.isfinite(mesh.vertices)):
        raise ConfigError(f"{what} {path} has coordinates that are not finite")
    return mesh


def check_folder_name(name: str, location: str = "name") -> None:
    """Check that ``name`` is one folder name, so that ``out/<name>`` stays in ``out``.

    Default output folders are named after scenarios and sweeps: a name must
    not reach outside (``../x``, ``/tmp/x``), be hidden (``.x``, where the
    staging folders go) or hold control characters.

    Raises:
        ConfigError: located at ``location``, saying what is wrong.
    """
    problem = ""
    if not name or len(name) > MAX_NAME_LENGTH:
        problem = f"must have 1 to {MAX_NAME_LENGTH} characters"
    elif "/" in name or "\\" in name:
        problem = "must be one folder name, without '/' or '\\'"
    elif name.startswith("."):
        problem = "must not start with '.'"
    elif not name.isprintable():
        problem = "must not hold control characters"
    if problem:
        raise ConfigError(
            f"{problem} (it names the output folder), got {name[:40]!r}", location
        )


def check_output_folder(out: Path, replace: bool = True) -> None:
    """Check that ``out`` may receive a run's outputs (before the run starts).

    It may be missing, empty, or (with ``replace``) an earlier output: it
    holds ``metrics.json`` or ``report.md``. Anything else is refused rather
    than replaced.

    Raises:
        ConfigError: ``out`` is a file, a folder of something else, or not
            empty when nothing may be replaced.
    """
    if not out.exists():
        return
    if not out.is_dir():
        raise ConfigError(f"output folder {out} is a file")
    if not any(out.iterdir()):
        return
    if not replace:
        raise ConfigError(
            f"output folder {out} is not empty; choose a new or empty folder "
            "(these outputs never replace earlier ones)"
        )
    if not any((out / m).exists() for m in OUTPUT_MARKERS):
        raise ConfigError(
            f"output folder {out} holds files that are not a cbp output; choose an "
            "empty or new folder (cbp replaces its own outputs only)"
        )


class OutputClaim:
    """A staging folder beside an output folder, locked while this process lives.

    Outputs are written into :attr:`staging`; :meth:`publish` puts the folder
    in place as :attr:`out`, and :meth:`put` adds files to it one by one
    afterwards. The staging folder is locked (``flock``) for as long as it is
    open here: the kernel drops the lock when the process ends, however it
    ends, so a staging folder nobody holds is the remains of a dead process
    and the next claim on the same output removes it. After :meth:`publish`
    a fresh staging folder is held, so the output stays claimed until
    :meth:`release`.

    Attributes:
        out: the output folder.
        staging: the folder files are written into before they are put in place.
        replace: whether an earlier output at :attr:`out` may be replaced.
    """

    def __init__(
        self, out: Path, staging: Path, descriptor: int, replace: bool = True
    ) -> None:
        """Hold ``staging`` (locked through ``descriptor``) for ``out``."""
        self.out = out
        self.staging = staging
        self.replace = replace
        self._descriptor: int | None = descriptor
        self._published: tuple[int, int] | None = None  # (device, inode) of out

    @property
    def released(self) -> bool:
        """Whether the claim has ended (its folder published, kept or removed)."""
        return self._descriptor is None

    def release(self, remove: bool = False) -> None:
        """Drop the lock; with ``remove``, delete the staging folder first.

        Once released, a claim does nothing more (a second call is harmless).
        """
        if remove and self._descriptor is not None:
            shutil.rmtree(self.staging, ignore_errors=True)
        if self._descriptor is not None:
            os.close(self._descriptor)
            self._descriptor = None

    def publish(self) -> None:
        """Put the staging folder in place as :attr:`out`, as a whole.

        An earlier output at ``out`` is replaced as a whole: under a lock on
        the folder that holds ``out``, it is renamed aside and the staging
        folder renamed into its place (both renames are atomic on one file
        system), so concurrent writers leave exactly one complete output
        there, and a reader never sees a mixture. A fresh staging folder is
        then held for the files :meth:`put` adds.

        Raises:
            ConfigError: ``out`` is not a cbp output, or (without
                :attr:`replace`) not empty; the staging folder is kept and
                the message names it.
        """
        out, old = self.out, None
        with _locked(out.parent):
            try:
                check_output_folder(out, self.replace)
            except ConfigError as exc:
                raise ConfigError(
                    f"{exc.message}; the outputs are in {self.staging}"
                ) from None
            if out.exists():
                old = out.parent / f".{out.name}.old-{secrets.token_hex(4)}"
                os.replace(out, old)
            os.replace(self.staging, out)
            published = out.stat()
            self._published = (published.st_dev, published.st_ino)
            staging, descriptor = _staging_folder(out)
            if self._descriptor is not None:
                os.close(self._descriptor)
            self.staging, self._descriptor = staging, descriptor
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def put(self, name: str) -> bool:
        """Move the file ``name`` of the staging folder into the published output.

        One rename on one file system: the file appears whole or not at all.
        When a later output has replaced this one meanwhile (a run that
        claimed the folder without refusing live ones), the file is dropped:
        outputs never mix.

        Returns:
            Whether the file was put in place.
        """
        source = self.staging / name
        with _locked(self.out.parent):
            try:
                now = self.out.stat()
            except OSError:
                now = None
            if now is not None and (now.st_dev, now.st_ino) == self._published:
                os.replace(source, self.out / name)
                return True
        source.unlink(missing_ok=True)
        return False


def claim_output_folder(
    out: Path, refuse_live: bool = True, replace: bool = True
) -> OutputClaim:
    """Check ``out`` (:func:`check_output_folder`) and claim it for this process.

    Staging folders beside ``out`` (``.NAME.part-PID-HEX``) that no live
    process holds are removed, as are folders left renamed aside
    (``.NAME.old-HEX``).

    Args:
        out: the output folder.
        refuse_live: refuse when another live run holds a staging folder for
            ``out`` (else both write and the last to finish replaces the other).
        replace: whether an earlier output at ``out`` may be replaced (else a
            folder that is not empty is refused, now and when publishing).

    Raises:
        ConfigError: ``out`` is not a cbp output, not empty without
            ``replace``, or in use by a live run (the message names its
            process).
    """
    check_output_folder(out, replace)
    out.parent.mkdir(parents=True, exist_ok=True)
    prefix = f".{out.name}."
    with _locked(out.parent):
        for other in out.parent.iterdir():
            if not other.name.startswith(prefix):
                continue
            kind = other.name[len(prefix) :].split("-", 1)[0]
            if kind == "old" or (kind == "part" and not _held(other)):
                shutil.rmtree(other, ignore_errors=True)  # a dead process's
            elif kind == "part" and refuse_live:
                pid = other.name[len(prefix) :].split("-")[1]
                raise ConfigError(
                    f"output folder {out} is in use by a run still going (process "
                    f"{pid}, writing {other.name}); wait for it to end or choose "
                    "another folder"
                )
        if out.name and (out.parent / f".{out.name}.lock").is_file():
            (out.parent / f".{out.name}.lock").unlink()  # left by earlier versions
        staging, descriptor = _staging_folder(out)
    return OutputClaim(out, staging, descriptor, replace)


def claim_new_output_folder(out: Path, attempts: int = 1000) -> OutputClaim:
    """Claim ``out``, or ``out_2``, ``out_3``...: the first that nothing occupies.

    A folder is taken when it is not empty or a live run claims it; the one
    claimed is never replaced when published (a new folder per session).

    Raises:
        ConfigError: the last refusal, when ``attempts`` folders are taken.
    """
    for k in range(1, attempts + 1):
        folder = out if k == 1 else out.with_name(f"{out.name}_{k}")
        try:
            return claim_output_folder(folder, replace=False)
        except ConfigError:
            if k == attempts:
                raise
    raise AssertionError("unreachable: the loop returns or raises")


def _staging_folder(out: Path) -> tuple[Path, int]:
    """A new staging folder beside ``out``, and the descriptor that locks it."""
    staging = out.parent / f".{out.name}.part-{os.getpid()}-{secrets.token_hex(4)}"
    staging.mkdir()
    descriptor = os.open(staging, os.O_RDONLY)
    fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return staging, descriptor


def _held(folder: Path) -> bool:
    """Whether a live process holds the lock on ``folder`` (an OutputClaim)."""
    try:
        descriptor = os.open(folder, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(descriptor)
    return False


@contextlib.contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``folder`` itself (no lock file is made)."""
    descriptor = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)
        yield
    finally:
        os.close(descriptor)
