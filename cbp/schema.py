# SPDX-License-Identifier: Apache-2.0
"""Strict YAML to frozen-dataclass loading with located, collected error messages.

A schema is a dataclass. Its fields' annotations say what a YAML value may be:
``float``, ``int``, ``str``, ``bool``, ``Literal[...]``, ``X | None``, ``tuple[float,
...]`` (any length), ``tuple[float, float, float]`` (fixed length), ``list[X]``,
``dict[str, X]``, another dataclass, or ``Any`` (taken as parsed). Unknown keys,
missing required keys, wrong types and wrong lengths are all reported, each with the
file, the line, the path in the document and the closest valid choice, and all the
problems of one file are reported together (:class:`~cbp.errors.ScenarioError`).
"""

from __future__ import annotations

import ast
import dataclasses
import datetime
import inspect
import itertools
import math
import re
import textwrap
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar

import yaml

from cbp.data import config_path, is_file
from cbp.errors import ConfigError, ScenarioError, suggestion
from cbp.files import read_text

T = TypeVar("T")

Node = yaml.Node


class _Missing:
    """Marker for a value that could not be built (its problem is already recorded)."""

    def __repr__(self) -> str:
        return "<invalid>"


INVALID: Any = _Missing()


def join_path(base: str, key: str | int) -> str:
    """Append a mapping key or a sequence index to a document path."""
    if isinstance(key, int):
        return f"{base}[{key}]"
    return f"{base}.{key}" if base else key


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
        self.root: Node | None = _compose(text, path)
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
        other.root = _copy_tree(self.root, {})
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
            value = _compose(text, label)
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
        return _build(self, tp, node, where)


#: Largest magnitude of a number in a file: beyond it, squares and products of
#: positions, sizes and gains overflow. Integers have the same bound (counts
#: that size memory or loops have tighter ones of their own).
MAX_MAGNITUDE = 1e12
#: Deepest nesting of lists and mappings accepted in a file.
MAX_DEPTH = 64
#: Most values in a file, counting each use of an alias as a copy of what it
#: names (so that a few lines of aliases cannot expand into millions of values).
MAX_VALUES = 200_000

#: The tags a file may use: the plain values YAML resolves by itself.
_PLAIN_TAGS = {
    f"tag:yaml.org,2002:{name}"
    for name in ("str", "int", "float", "bool", "null", "seq", "map", "timestamp")
}
_MERGE_TAG = "tag:yaml.org,2002:merge"
_COLLECTION_TAGS: dict[type[Node], str] = {
    yaml.MappingNode: "tag:yaml.org,2002:map",
    yaml.SequenceNode: "tag:yaml.org,2002:seq",
}


class Loader(yaml.SafeLoader):
    """PyYAML's safe loader, reading YAML 1.2's numbers as numbers.

    YAML 1.1 (PyYAML's default) wants a dot and a signed exponent in a float, so
    ``1e-3``, ``1.5e1``, ``1.0e12`` and ``.5e3`` would be strings; YAML 1.2
    reads them all as numbers, and so does this loader. (YAML 1.1's other forms,
    ``1_000`` and ``0x1f``, still read as numbers too.)
    """


Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:\.[0-9]+|[0-9][0-9_]*(?:\.[0-9_]*)?)(?:[eE][-+]?[0-9]+)$"),
    list("-+.0123456789"),
)


def _compose(text: str, name: str) -> Node | None:
    """Parse ``text`` into a node tree; any YAML error is a located ScenarioError."""
    loader: Loader | None = None
    try:
        loader = Loader(text)  # refuses control characters here
        loader.name = name  # marks (and so error lines) name the file
        return loader.get_single_node()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f"line {mark.line + 1}: " if mark is not None else ""
        raise ScenarioError(
            name, [f"{line}malformed YAML: {exc.problem or exc}"]
        ) from None
    except yaml.reader.ReaderError as exc:  # a character YAML does not accept
        before = text[: exc.position]
        column = exc.position - (before.rfind("\n") + 1) + 1
        raise ScenarioError(
            name,
            [
                f"line {before.count(chr(10)) + 1}, column {column}: malformed "
                "YAML: unacceptable "
                f"character #x{exc.character:04x} (control characters are not "
                "allowed; write them as escapes in a double-quoted string)"
                if isinstance(exc.character, int)
                else f"line {before.count(chr(10)) + 1}: malformed YAML: "
                f"{str(exc).splitlines()[0]}"
            ],
        ) from None
    except yaml.YAMLError as exc:
        message = str(exc).split("\n")[0]
        raise ScenarioError(name, [f"malformed YAML: {message}"]) from None
    except RecursionError:  # the parser got this far into the nesting
        deep = loader.line + 1 if loader is not None else 1
        raise ScenarioError(
            name,
            [
                f"line {deep}: malformed YAML: nested too deeply (at most "
                f"{MAX_DEPTH} levels)"
            ],
        ) from None


def check_tree(doc: Document, root: Node | None) -> list[str]:
    """Problems that stop a node tree from being read at all, each located.

    Tags other than the plain ones (``!custom``, ``!!binary``, ``!!set``, the
    merge key ``<<``), values their tag cannot build (``!!float abc``, a date
    that does not exist, an integer of thousands of digits), aliases that
    contain themselves, nesting deeper than :data:`MAX_DEPTH` and more than
    :data:`MAX_VALUES` values once aliases are expanded.
    """
    if root is None:
        return []
    problems: list[str] = []

    def where(node: Node) -> str:
        return f"line {node.start_mark.line + 1}"

    sizes: dict[int, int] = {}
    # Depth-first, iteratively (a deep file must not exhaust Python's stack):
    # (node, depth, children pushed?)
    stack: list[tuple[Node, int, bool]] = [(root, 1, False)]
    open_nodes: set[int] = set()
    while stack:
        node, depth, expanded = stack.pop()
        key = id(node)
        if expanded:
            open_nodes.discard(key)
            children = _children(node)
            sizes[key] = 1 + sum(sizes.get(id(c), 0) for c in children)
            if sizes[key] > MAX_VALUES:  # the smallest value that is too large
                problems.append(
                    f"{where(node)}: this value holds {sizes[key]} values once "
                    f"aliases are expanded, more than the {MAX_VALUES} accepted in "
                    "a file"
                )
                return problems
            continue
        if key in sizes:
            continue
        if key in open_nodes:
            problems.append(
                f"{where(node)}: an alias refers to a value that contains it"
            )
            return problems
        if depth > MAX_DEPTH:
            problems.append(f"{where(node)}: nested more than {MAX_DEPTH} levels deep")
            return problems
        if node.tag == _MERGE_TAG:
            problems.append(
                f"{where(node)}: the merge key '<<' is not supported; write the keys "
                "out, or put shared sections in a file named by 'include:'"
            )
            continue
        if node.tag not in _PLAIN_TAGS:
            problems.append(
                f"{where(node)}: the tag '{node.tag}' is not supported; use plain "
                "numbers, strings, true/false, null, lists and mappings"
            )
            continue
        if isinstance(node, yaml.ScalarNode):
            sizes[key] = 1
            problem = _scalar_problem(doc, node)
            if problem:
                problems.append(f"{where(node)}: {problem}")
            continue
        if node.tag != _COLLECTION_TAGS.get(type(node)):
            kind = node.tag.rsplit(":", 1)[-1]
            problems.append(
                f"{where(node)}: the tag '!!{kind}' cannot be given to "
                f"{'a mapping' if isinstance(node, yaml.MappingNode) else 'a list'}"
            )
            continue
        open_nodes.add(key)
        stack.append((node, depth, True))
        stack.extend((child, depth + 1, False) for child in reversed(_children(node)))
    return problems


def _copy_tree(node: Node | None, copies: dict[int, Node]) -> Node | None:
    """Copy the mappings and lists of a node tree (see :meth:`Document.copy`)."""
    if node is None or isinstance(node, yaml.ScalarNode):
        return node
    if id(node) in copies:
        return copies[id(node)]
    copy: Node
    if isinstance(node, yaml.MappingNode):
        copy = yaml.MappingNode(node.tag, [], node.start_mark, node.end_mark)
        copies[id(node)] = copy
        copy.value = [
            (_copy_tree(k, copies), _copy_tree(v, copies)) for k, v in node.value
        ]
    else:
        copy = yaml.SequenceNode(node.tag, [], node.start_mark, node.end_mark)
        copies[id(node)] = copy
        copy.value = [_copy_tree(v, copies) for v in node.value]
    return copy


def _children(node: Node) -> list[Node]:
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def _scalar_problem(doc: Document, node: yaml.ScalarNode) -> str:
    """Why the scalar cannot be read, or an empty string."""
    kind = node.tag.rsplit(":", 1)[-1]
    try:
        value = doc.scalar(node)
    except Exception as exc:  # PyYAML's constructors raise many types here
        reason = getattr(exc, "problem", None) or str(exc).split("\n")[0]
        if isinstance(exc, KeyError | AttributeError | TypeError):
            reason = "not a valid value of this tag"  # !!bool maybe, !!timestamp x
        return f"cannot read {node.value[:40]!r} as {kind}: {reason}"
    if isinstance(value, datetime.date):
        return (
            f"{node.value[:40]!r} reads as a date, which no setting takes; quote "
            "it to make it a string"
        )
    if isinstance(value, int) and not isinstance(value, bool):
        try:
            float(value)
        except OverflowError:
            return f"the integer {node.value[:20]}... is too large for a number"
    return ""


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


def mapping_items(doc: Document, node: Node, where: str) -> dict[str, Node] | None:
    """Return a mapping node's items keyed by string, or record a problem."""
    if not isinstance(node, yaml.MappingNode):
        doc.report(node, where, f"expected a mapping, got {_describe(doc, node)}")
        return None
    items: dict[str, Node] = {}
    for key_node, value_node in node.value:
        key = doc.scalar(key_node) if isinstance(key_node, yaml.ScalarNode) else None
        if not isinstance(key, str):
            doc.report(key_node, where, "mapping keys must be strings")
            continue
        if key in items:
            doc.report(key_node, join_path(where, key), "duplicate key")
        items[key] = value_node
    return items


def key_nodes(node: Node) -> dict[str, Node]:
    """A mapping node's key nodes by key, to report a problem with the key itself.

    A key's own line is its node's; its value's node may start on a later line
    (a block value) or at another column (a flow value). Keys without a mark
    are left out: their problems are reported at the value.
    """
    if not isinstance(node, yaml.MappingNode):
        return {}
    return {
        str(key_node.value): key_node
        for key_node, _ in node.value
        if isinstance(key_node, yaml.ScalarNode) and key_node.start_mark is not None
    }


def type_name(tp: Any) -> str:
    """Describe an annotation in words a YAML author understands."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is str:
        return "a string"
    if tp is bool:
        return "true or false"
    if tp is Any:
        return "any value"
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (types.UnionType, typing.Union):
        parts = [type_name(a) for a in args if a is not type(None)]
        return " or ".join(parts) + (" or null" if type(None) in args else "")
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_plural(args[0])}"
        return f"a list of {len(args)} {_plural(args[0])}"
    if origin is list:
        return f"a list of {_plural(args[0])}"
    if origin is dict:
        return f"a mapping of names to {_plural(args[1])}"
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return f"a mapping ({tp.__name__})"
    return getattr(tp, "__name__", str(tp))


def _plural(tp: Any) -> str:
    return {float: "numbers", int: "integers", str: "strings", bool: "booleans"}.get(
        tp, "entries"
    )


def _describe(doc: Document, node: Node | None) -> str:
    if node is None:
        return "nothing"
    if isinstance(node, yaml.MappingNode):
        return "a mapping"
    if isinstance(node, yaml.SequenceNode):
        return f"a list of {len(node.value)} entries"
    value = doc.plain(node)
    if value is None:
        return "null"
    return f"{type(value).__name__} {value!r}"


def _build(doc: Document, tp: Any, node: Node | None, where: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is Any:
        return None if node is None else doc.plain(node)
    if origin in (types.UnionType, typing.Union):
        return _build_union(doc, args, node, where)
    if dataclasses.is_dataclass(tp):
        return _build_dataclass(doc, typing.cast(type, tp), node, where)
    if origin is tuple or origin is list:
        return _build_sequence(doc, tp, node, where)
    if origin is dict:
        return _build_dict(doc, args[1], node, where)
    if node is None or not isinstance(node, yaml.ScalarNode):
        doc.report(node, where, f"expected {type_name(tp)}, got {_describe(doc, node)}")
        return INVALID
    value = doc.scalar(node)
    return _check_scalar(doc, tp, value, node, where)


def _check_scalar(doc: Document, tp: Any, value: Any, node: Node, where: str) -> Any:
    origin = typing.get_origin(tp)
    if origin is Literal:
        choices = typing.get_args(tp)
        if value in choices and type(value) is type(choices[0]):
            return value
        hint = suggestion(str(value), [str(c) for c in choices])
        doc.report(
            node,
            where,
            f"got {value!r}, expected {type_name(tp)}{hint}",
        )
        return INVALID
    # bool is a subclass of int: a YAML `yes` must not pass as a number.
    if tp is float and isinstance(value, int | float) and not isinstance(value, bool):
        if math.isfinite(value) and abs(value) <= MAX_MAGNITUDE:
            return float(value)
        doc.report(
            node,
            where,
            f"expected a finite number of magnitude at most {MAX_MAGNITUDE:g}, "
            f"got {value:g}",
        )
        return INVALID
    if tp is int and isinstance(value, int) and not isinstance(value, bool):
        if abs(value) <= MAX_MAGNITUDE:
            return value
        doc.report(
            node,
            where,
            f"expected an integer of magnitude at most {MAX_MAGNITUDE:.0f}, "
            f"got {node.value if isinstance(node, yaml.ScalarNode) else value}"[:200],
        )
        return INVALID
    if tp is str and isinstance(value, str):
        return value
    if tp is bool and isinstance(value, bool):
        return value
    doc.report(node, where, f"expected {type_name(tp)}, got {_describe(doc, node)}")
    return INVALID


def _build_union(
    doc: Document, args: tuple[Any, ...], node: Node | None, where: str
) -> Any:
    optional = type(None) in args
    if (
        node is None
        or (isinstance(node, yaml.ScalarNode) and doc.scalar(node) is None and optional)
    ) and optional:
        return None
    members = [a for a in args if a is not type(None)]
    if len(members) == 1:  # X | None: X's own problems are the useful ones
        return _build(doc, members[0], node, where)
    # Try each member on a scratch document state; keep the first that builds.
    for member in members:
        saved = len(doc.problems)
        value = _build(doc, member, node, where)
        if value is not INVALID:
            return value
        del doc.problems[saved:]
    expected = type_name(typing.Union[tuple(args)])  # noqa: UP007
    doc.report(node, where, f"expected {expected}, got {_describe(doc, node)}")
    return INVALID


def _build_sequence(doc: Document, tp: Any, node: Node | None, where: str) -> Any:
    args = typing.get_args(tp)
    if not isinstance(node, yaml.SequenceNode):
        doc.report(node, where, f"expected {type_name(tp)}, got {_describe(doc, node)}")
        return INVALID
    variadic = typing.get_origin(tp) is list or (len(args) == 2 and args[1] is Ellipsis)
    if not variadic and len(node.value) != len(args):
        doc.report(
            node,
            where,
            f"expected {type_name(tp)}, got a list of {len(node.value)} entries",
        )
        return INVALID
    item_types = [args[0]] * len(node.value) if variadic else list(args)
    items = [
        _build(doc, item_tp, item, join_path(where, i))
        for i, (item_tp, item) in enumerate(zip(item_types, node.value, strict=True))
    ]
    if any(item is INVALID for item in items):
        return INVALID
    return list(items) if typing.get_origin(tp) is list else tuple(items)


def _build_dict(doc: Document, value_tp: Any, node: Node | None, where: str) -> Any:
    items = mapping_items(doc, node, where) if node is not None else None
    if items is None:
        if node is None:
            doc.report(node, where, "expected a mapping, got nothing")
        return INVALID
    built = {k: _build(doc, value_tp, v, join_path(where, k)) for k, v in items.items()}
    return INVALID if any(v is INVALID for v in built.values()) else built


def _build_dataclass(
    doc: Document, cls: type, node: Node | None, where: str, base: Any = None
) -> Any:
    """Build ``cls`` from ``node``; keys it leaves out keep ``base``'s values.

    Without ``base``, a left-out key takes the field's default. A section
    given in part (``timing: {clock: virtual}``) starts from its field's
    default in the parent (``MpSettings.timing`` has MP's period, not the
    class's own), so that it changes only the keys it names.
    """
    if node is None or (isinstance(node, yaml.ScalarNode) and doc.scalar(node) is None):
        items: dict[str, Node] | None = {}
    else:
        items = mapping_items(doc, node, where)
    if items is None:
        return INVALID
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    ok = True
    keys = key_nodes(node) if node is not None else {}
    for key, value_node in items.items():
        if key not in fields:
            accepted = ", ".join(fields) or "(none)"
            doc.report(
                keys.get(key, value_node),
                join_path(where, key),
                f"unknown key '{key}'{suggestion(key, fields)} Accepted: {accepted}.",
            )
            ok = False
    kwargs: dict[str, Any] = {}
    for name, field in fields.items():
        if name in items:
            tp, path = hints[name], join_path(where, name)
            default = (
                getattr(base, name)
                if base is not None
                else field.default_factory()
                if field.default_factory is not dataclasses.MISSING
                else None
            )
            value = (
                _build_dataclass(doc, type(default), items[name], path, default)
                if dataclasses.is_dataclass(default)
                and type(default) is tp
                and isinstance(items[name], yaml.MappingNode)
                else _build(doc, tp, items[name], path)
            )
            if value is INVALID:
                ok = False
            else:
                kwargs[name] = value
        elif base is not None:
            kwargs[name] = getattr(base, name)
        elif (
            field.default is dataclasses.MISSING
            and field.default_factory is dataclasses.MISSING
        ):
            doc.report(
                node,
                join_path(where, name),
                f"missing required key '{name}' ({type_name(hints[name])})",
            )
            ok = False
    if not ok:
        return INVALID
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        key_node = items.get(exc.location.split(".")[0]) if exc.location else None
        doc.report(key_node or node, join_path(where, exc.location), exc.message)
        return INVALID


def load_file(cls: type[T], path: str | Path) -> T:
    """Load a whole YAML file into the dataclass ``cls``, or raise ScenarioError."""
    doc = Document.from_file(path)
    value = doc.build(cls, doc.root, "")
    doc.raise_if_problems()
    return typing.cast(T, value)


def to_plain(value: Any) -> Any:
    """Turn a dataclass (or nested containers of them) back into YAML-ready data."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {
            f.name: to_plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if f.init
        }
    if isinstance(value, tuple | list):
        return [to_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: to_plain(v) for k, v in value.items()}
    return value


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


def field_docs(cls: type) -> dict[str, str]:
    """The docstring after each field of a dataclass, its bases' included.

    Read from the source (the string that follows a field); {} when there is
    none to read.
    """
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if klass is object or not dataclasses.is_dataclass(klass):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError):
            continue
        body = next((n.body for n in tree.body if isinstance(n, ast.ClassDef)), [])
        for prev, node in itertools.pairwise(body):
            if (
                isinstance(prev, ast.AnnAssign)
                and isinstance(prev.target, ast.Name)
                and isinstance(node, ast.Expr)
                and isinstance(node.value, ast.Constant)
                and isinstance(node.value.value, str)
            ):
                docs[prev.target.id] = " ".join(node.value.value.split())
    return docs


def value_node(root: Node | None, *keys: str) -> Node | None:
    """The node at ``keys`` in a tree of mappings, or None where there is none."""
    node = root
    for key in keys:
        if not isinstance(node, yaml.MappingNode):
            return None
        node = next(
            (
                v
                for k, v in node.value
                if isinstance(k, yaml.ScalarNode) and k.value == key
            ),
            None,
        )
    return node
