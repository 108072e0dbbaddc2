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

:func:`missing_meshes` finds, the same way, every mesh a URDF names that no
file answers, with its link and line, so that a robot with a missing mesh is
refused when it is loaded rather than when PyBullet or pinocchio reads it.
"""

from __future__ import annotations

import os
import re
import shutil
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from xml.parsers import expat

from cbp.errors import ConfigError
from cbp.files import MAX_YAML_BYTES, read_text

__all__ = [
    "CopiedUrdf",
    "MeshUse",
    "copy_urdf",
    "mesh_uses",
    "missing_meshes",
    "resolve_mesh",
]

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


@dataclass(frozen=True)
class MeshUse:
    """A ``<mesh filename=...>`` of a URDF, where it stands.

    Attributes:
        link: the ``<link>`` it belongs to.
        element: ``visual`` or ``collision``.
        filename: the file name as the URDF writes it.
        line: its line in the URDF (1-based).
    """

    link: str
    element: str
    filename: str
    line: int

    @property
    def missing(self) -> str:
        """What to say when no file answers it (the caller adds the URDF and line)."""
        return (
            f"link '{self.link}': cannot find its {self.element} mesh '{self.filename}'"
        )


def ros_package_dirs() -> list[Path]:
    """The folders ROS looks up ``package://`` names under, from the environment.

    ``ROS_PACKAGE_PATH`` (ROS 1) and each ``AMENT_PREFIX_PATH`` prefix's
    ``share`` folder (ROS 2), as pinocchio and the ROS tools read them; none
    when neither is set.
    """
    dirs = [Path(d) for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)]
    prefixes = os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
    dirs += [Path(p) / "share" for p in prefixes if p]
    return [d for d in dirs if str(d) not in ("", ".")]


def resolve_mesh(
    name: str, urdf_folder: Path, package_dirs: Sequence[Path] = ()
) -> tuple[Path, str] | None:
    """The file a URDF mesh name points to, and its path inside a robot folder.

    Args:
        name: the mesh's file name as the URDF writes it.
        urdf_folder: the URDF's folder.
        package_dirs: more folders a ``package://`` name is looked up under
            (after the URDF's folder and the folders above it).

    Returns:
        (file, relative destination), or None when no file answers the name.
    """
    if name.startswith("package://"):
        rest = name[len("package://") :]
        folders = [urdf_folder, *list(urdf_folder.parents)[:PACKAGE_LEVELS]]
        for folder in [*folders, *package_dirs, *ros_package_dirs()]:
            if (folder / rest).is_file():
                return folder / rest, _inside(rest)
        return None
    path = Path(name[len("file://") :] if name.startswith("file://") else name)
    if path.is_absolute():
        return (path, _inside(f"meshes/{path.name}")) if path.is_file() else None
    return (
        (urdf_folder / path, _inside(name)) if (urdf_folder / path).is_file() else None
    )


def mesh_uses(urdf: Path) -> list[MeshUse]:
    """Every ``<mesh>`` of a link's ``<visual>`` or ``<collision>``, with its line.

    Raises:
        ConfigError: the URDF cannot be read or parsed.
    """
    text = read_text(urdf, "URDF", MAX_YAML_BYTES * 8)
    parser = expat.ParserCreate()
    uses: list[MeshUse] = []
    stack: list[tuple[str, str]] = []  # (tag, name) of the open elements

    def start(tag: str, attributes: dict[str, str]) -> None:
        stack.append((tag, attributes.get("name", "")))
        filename = attributes.get("filename", "")
        if tag != "mesh" or not filename:
            return
        tags = [t for t, _ in stack]
        element = next((t for t in reversed(tags) if t in _ELEMENTS), None)
        link = next((n for t, n in reversed(stack) if t == "link"), None)
        if element is not None and link is not None:
            uses.append(MeshUse(link, element, filename, parser.CurrentLineNumber))

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: stack.pop()
    try:
        parser.Parse(text, True)
    except expat.ExpatError as exc:
        raise ConfigError(f"cannot parse URDF {urdf}: {exc}") from None
    return uses


#: The elements of a link whose meshes are loaded.
_ELEMENTS = ("visual", "collision")


def missing_meshes(urdf: Path, package_dirs: Sequence[Path] = ()) -> list[MeshUse]:
    """The meshes of ``urdf`` that no file answers (:func:`resolve_mesh`), in order.

    Raises:
        ConfigError: the URDF cannot be read or parsed.
    """
    folder = urdf.resolve().parent
    return [
        use
        for use in mesh_uses(urdf)
        if resolve_mesh(use.filename, folder, package_dirs) is None
    ]


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
