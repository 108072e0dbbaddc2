# SPDX-License-Identifier: Apache-2.0
"""Copy a URDF and the mesh files it names into a robot folder.

A robot folder written by ``cbp robot init`` should work wherever it is moved
to: with the URDF in it, and every mesh the URDF names (``<mesh
filename=...>``, collision and visual) copied beside it and named by a path
relative to the copy. A mesh is found the way ROS tools and pinocchio find it:
``package://pkg/rest`` under the URDF's folder or one of the folders above
it, a relative path under the URDF's folder, ``file://`` or an absolute path
as it is. An ``.obj`` mesh's material files (``mtllib``) and their textures
are copied with it, and so is a licence file beside the URDF.
"""

from __future__ import annotations

import re
import shutil
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from cbp.errors import ConfigError
from cbp.files import MAX_YAML_BYTES, read_text

__all__ = ["CopiedUrdf", "copy_urdf", "resolve_mesh"]

#: Folders above the URDF's searched for ``package://`` meshes (a ROS tree).
PACKAGE_LEVELS = 3


@dataclass(frozen=True)
class CopiedUrdf:
    """What :func:`copy_urdf` wrote.

    Attributes:
        urdf: the copied URDF.
        meshes: the files copied beside the URDF (meshes, materials, licence),
            relative to the folder.
        missing: mesh names of the URDF that no file answers (left as they were).
    """

    urdf: Path
    meshes: list[str]
    missing: list[str]


def resolve_mesh(name: str, urdf_folder: Path) -> tuple[Path, str] | None:
    """The file a URDF mesh name points to, and its path inside a robot folder.

    Returns:
        (file, relative destination), or None when no file answers the name.
    """
    if name.startswith("package://"):
        rest = name[len("package://") :]
        for folder in [urdf_folder, *list(urdf_folder.parents)[:PACKAGE_LEVELS]]:
            if (folder / rest).is_file():
                return folder / rest, _inside(rest)
        return None
    path = Path(name[len("file://") :] if name.startswith("file://") else name)
    if path.is_absolute():
        return (path, _inside(f"meshes/{path.name}")) if path.is_file() else None
    return (
        (urdf_folder / path, _inside(name)) if (urdf_folder / path).is_file() else None
    )


def _inside(relative: str) -> str:
    """A relative path kept inside the folder (``..`` and roots dropped)."""
    parts = [p for p in PurePosixPath(relative).parts if p not in ("..", ".", "/")]
    return "/".join(parts) or "mesh"


def copy_urdf(urdf: Path, out: Path, name: str = "robot.urdf") -> CopiedUrdf:
    """Copy ``urdf`` to ``out/name`` and its meshes under ``out``, renamed relative.

    The URDF's text is kept as it is but for the mesh file names.

    Raises:
        ConfigError: the URDF cannot be read or parsed.
    """
    text = read_text(urdf, "URDF", MAX_YAML_BYTES * 8)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ConfigError(f"cannot parse URDF {urdf}: {exc}") from None
    names = sorted({m.get("filename", "") for m in root.iter("mesh")} - {""})
    folder = urdf.resolve().parent
    out.mkdir(parents=True, exist_ok=True)
    renamed: dict[str, str] = {}
    copied: list[str] = []
    missing: list[str] = []
    taken: dict[str, Path] = {}
    for mesh in names:
        found = resolve_mesh(mesh, folder)
        if found is None:
            missing.append(mesh)
            continue
        source, relative = found
        relative = _free_name(relative, source, taken)
        renamed[mesh] = relative
        for extra_source, extra in _with_materials(source, relative):
            if extra not in taken:
                taken[extra] = extra_source
                (out / extra).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(extra_source, out / extra)
                copied.append(extra)
    for old, new in renamed.items():
        text = text.replace(f'filename="{old}"', f'filename="{new}"')
        text = text.replace(f"filename='{old}'", f"filename='{new}'")
    target = out / name
    target.write_text(text)
    for notice in sorted(folder.glob("LICEN[CS]E*")) + sorted(folder.glob("COPYING*")):
        if notice.is_file() and not (out / notice.name).exists():
            shutil.copyfile(notice, out / notice.name)
            copied.append(notice.name)
    return CopiedUrdf(target, copied, missing)


def _free_name(relative: str, source: Path, taken: dict[str, Path]) -> str:
    """``relative``, or a numbered variant when another file already has it."""
    candidate, n = relative, 1
    while candidate in taken and taken[candidate].resolve() != source.resolve():
        stem = PurePosixPath(relative)
        candidate = str(stem.with_name(f"{stem.stem}_{n}{stem.suffix}"))
        n += 1
    return candidate


_MTLLIB = re.compile(r"^\s*mtllib\s+(.+?)\s*$", re.MULTILINE)
_TEXTURE = re.compile(r"^\s*(?:map_\w+|bump|disp|decal|refl)\s+(?:-\S+\s+)*(\S+)\s*$")


def _with_materials(source: Path, relative: str) -> list[tuple[Path, str]]:
    """The mesh, plus an ``.obj``'s material files and their textures, if present."""
    files = [(source, relative)]
    if source.suffix.lower() != ".obj":
        return files
    base = PurePosixPath(relative).parent
    text = source.read_text(errors="replace")
    for library in _MTLLIB.findall(text):
        mtl = source.parent / library
        if not mtl.is_file():
            continue
        files.append((mtl, _inside(str(base / library))))
        for line in mtl.read_text(errors="replace").splitlines():
            match = _TEXTURE.match(line)
            if match and (source.parent / match.group(1)).is_file():
                image = match.group(1)
                files.append((source.parent / image, _inside(str(base / image))))
    return files
