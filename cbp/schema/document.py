# SPDX-License-Identifier: Apache-2.0
"""A parsed YAML file and its problems: includes, ``--set``, located messages."""

from __future__ import annotations

import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml

from cbp.data import config_path, is_file
from cbp.errors import ConfigError, ScenarioError
from cbp.files import read_text
from cbp.schema.reading import Loader, Node, check_tree, compose, copy_tree
from cbp.schema.values import INVALID, build_value

__all__ = ["Document", "from_plain", "load_file"]

T = TypeVar("T")


class Document:
    """A parsed YAML file: its node tree, and the problems found while reading it.

    Attributes:
        path: the file, as it should be shown to the user.
        root: the root node, or None for an empty document.
        problems: every problem found so far, each a located message.
    """

    def __init__(self, text: str, path: str = "<string>") -> None:
        """Compose ``text`` into nodes; a syntax error becomes a ScenarioError."""
        self.path = path
        self.problems: list[str] = []
        #: Included file -> (the file that includes it, the include line there).
        self._included_by: dict[str, tuple[str, str]] = {}
        self.root: Node | None = compose(text, path)
        self._loader = Loader("")
        self._loader.name = path
        problems = check_tree(self, self.root)
        if problems:
            raise ScenarioError(path, problems)

    @classmethod
    def from_file(cls, path: str | Path) -> Document:
        """Read a YAML file; an unreadable one is a ScenarioError naming it.

        Only regular files of at most :data:`~cbp.files.MAX_YAML_BYTES` in UTF-8
        are read.
        """
        try:
            text = read_text(Path(path), "file")
        except ConfigError as exc:
            raise ScenarioError(str(path), [exc.message]) from None
        return cls(text, str(path))

    def copy(self) -> Document:
        """A copy whose tree :meth:`override` can change, leaving this one as it is.

        Mappings and lists are copied (aliases stay shared); scalars, which
        nothing changes in place, are shared.
        """
        other = Document("", self.path)  # its own loader, an empty tree
        other.problems = list(self.problems)
        other.root = copy_tree(self.root, {})
        return other

    def report(self, node: Node | None, where: str, message: str) -> None:
        """Record a problem at ``where`` (a document path), with the node's line."""
        self.problems.append(self.located(node, where, message))

    def located(self, node: Node | None, where: str, message: str) -> str:
        """``message`` at ``where`` (a document path), after the node's line.

        The form of every problem :meth:`report` records, for a warning too.
        """
        line = ""
        mark = node.start_mark if node is not None else None
        if mark is not None:  # nodes made by --set have none
            line = f"line {mark.line + 1}: "
            name = mark.name
            if name.startswith("--set "):  # a command-line value: one line
                line = f"{name}: "
            elif name != self.path:
                line = f"{name}, {line}"
            # A value from an included file: the include lines that bring it in,
            # from this file's.
            while name in self._included_by:
                name, include = self._included_by[name]
                at = include if name == self.path else f"{name}, {include}"
                line = f"{at} -> {line}"
        return f"{line}{where or '<document>'}: {message}"

    def raise_if_problems(self) -> None:
        """Raise one ScenarioError that lists every problem recorded, once each.

        A node read by two passes reports its problem once.
        """
        if self.problems:
            raise ScenarioError(self.path, list(dict.fromkeys(self.problems)))

    def resolve_includes(self, key: str = "include") -> list[Path]:
        """Merge the top-level keys of the files named by ``key`` into the root.

        ``include: other.yaml`` (or a list of files), relative to this file, or
        the name of a configuration that ships with cbp (``include: cat``,
        :func:`cbp.data.shipped_configs`) when no such file is there. A key
        this file sets itself is kept as it is; the others are taken from the
        included files, in order, and their problems are reported with the
        included file's name and line. Included files may include others.

        Returns:
            The files merged in.
        """
        merged: list[Path] = []
        self._merge_includes(self.root, Path(self.path), key, merged)
        return merged

    def _merge_includes(
        self, root: Node | None, path: Path, key: str, merged: list[Path]
    ) -> None:
        if not isinstance(root, yaml.MappingNode):
            return
        entry = next(
            (
                (k, v)
                for k, v in root.value
                if isinstance(k, yaml.ScalarNode) and k.value == key
            ),
            None,
        )
        if entry is None:
            return
        root.value.remove(entry)
        node = entry[1]
        names = self.build(str | list[str], node, key)
        if names is INVALID:
            return
        for name in [names] if isinstance(names, str) else names:
            try:
                target = (path.parent / name).resolve()
            except (OSError, ValueError) as exc:  # a NUL byte, a loop of links
                self.report(node, key, f"cannot include {name!r}: {exc}")
                continue
            shipped = config_path(name)
            if shipped is not None and not is_file(target):
                target = shipped.resolve()  # include: cat
            if target in merged or target == Path(self.path).resolve():
                self.report(node, key, f"'{name}' is included twice (a cycle?)")
                continue
            try:
                included = Document.from_file(target)
            except ScenarioError as exc:
                self.report(node, key, "; ".join(exc.problems))
                continue
            merged.append(target)
            self._included_by[str(target)] = (
                str(path),
                f"line {node.start_mark.line + 1} ({key}: {name})",
            )
            self._merge_includes(included.root, target, key, merged)
            if not isinstance(included.root, yaml.MappingNode):
                self.report(node, key, f"'{name}' must hold a mapping of scenario keys")
                continue
            present = {k.value for k, _ in root.value if isinstance(k, yaml.ScalarNode)}
            for k, v in included.root.value:
                if isinstance(k, yaml.ScalarNode) and k.value not in present:
                    root.value.append((k, v))

    def override(self, dotted: str, text: str) -> None:
        """Set ``dotted`` (``a.b.c``) to the YAML value ``text``, before building.

        Missing mappings on the way are created. In a list, a key is an index
        (``constraints.2.gain``) or the ``name`` of an item, or its ``type`` when
        it has no name (``constraints.contact_normals.gain``). Problems with the
        value are reported against ``--set a.b.c``.
        """
        label = f"--set {dotted}"
        try:
            value = compose(text, label)
        except ScenarioError as exc:
            self.problems.append(
                f"{label}: malformed YAML value {text!r}: {'; '.join(exc.problems)}"
            )
            return
        if value is None:
            value = yaml.ScalarNode("tag:yaml.org,2002:null", "")
        problems = check_tree(self, value)
        if problems:
            self.problems += [f"{label}: {p}" for p in problems]
            return
        keys = dotted.split(".")

        def made_key(key: str) -> yaml.ScalarNode:
            # A key made here is reported, like its value, against ``--set``.
            mark = value.start_mark
            return yaml.ScalarNode("tag:yaml.org,2002:str", key, mark, mark)

        if self.root is None:
            self.root = yaml.MappingNode("tag:yaml.org,2002:map", [])
        node = self.root
        for i, key in enumerate(keys):
            if isinstance(node, yaml.SequenceNode) and i < len(keys) - 1:
                item = _list_item(node, key)
                if item is None:
                    where = ".".join(keys[:i])
                    self.problems.append(
                        f"{label}: '{where}' has no item {key!r} (an index, or "
                        "an item's name or type)"
                    )
                    return
                node = item
                continue
            if not isinstance(node, yaml.MappingNode):
                where = ".".join(keys[:i])
                self.problems.append(f"{label}: '{where}' is not a mapping")
                return
            entry = next(
                (
                    kv
                    for kv in node.value
                    if isinstance(kv[0], yaml.ScalarNode) and kv[0].value == key
                ),
                None,
            )
            if i == len(keys) - 1:
                if entry is not None:
                    node.value.remove(entry)
                node.value.append((made_key(key), value))
                return
            if entry is None:
                child = yaml.MappingNode("tag:yaml.org,2002:map", [])
                node.value.append((made_key(key), child))
                node = child
            else:
                node = entry[1]

    def scalar(self, node: yaml.ScalarNode) -> Any:
        """Return the Python value of a scalar node, typed by YAML's safe rules."""
        return self._loader.construct_object(node, deep=True)

    def plain(self, node: Node) -> Any:
        """Return the Python value of any node (mappings and lists included)."""
        return self._loader.construct_object(node, deep=True)

    def build(self, tp: Any, node: Node | None, where: str) -> Any:
        """Build a value of annotation ``tp`` from ``node``; INVALID on a problem."""
        return build_value(self, tp, node, where)


def _list_item(node: yaml.SequenceNode, key: str) -> Node | None:
    """The item of a YAML list at index ``key``, or named (else typed) ``key``."""
    if key.isdigit():
        index = int(key)
        return node.value[index] if index < len(node.value) else None
    for field in ("name", "type"):
        for item in node.value:
            if not isinstance(item, yaml.MappingNode):
                continue
            values = {
                k.value: v.value
                for k, v in item.value
                if isinstance(k, yaml.ScalarNode) and isinstance(v, yaml.ScalarNode)
            }
            if field == "type" and "name" in values:
                continue
            if values.get(field) == key:
                return item
    return None


def load_file(cls: type[T], path: str | Path) -> T:
    """Load a whole YAML file into the dataclass ``cls``, or raise ScenarioError."""
    doc = Document.from_file(path)
    value = doc.build(cls, doc.root, "")
    doc.raise_if_problems()
    return typing.cast(T, value)


def from_plain(cls: type[T], data: Mapping[str, Any], where: str = "") -> T:
    """Build ``cls`` from plain Python data with the same strict rules as YAML.

    Raises:
        ScenarioError: listing every problem, located by path.
    """
    text = yaml.safe_dump(dict(data), sort_keys=False, allow_unicode=True)
    doc = Document(text, where or f"<{cls.__name__}>")
    value = doc.build(cls, doc.root, "")
    doc.raise_if_problems()
    return typing.cast(T, value)
