# SPDX-License-Identifier: Apache-2.0
"""Values built from nodes by their annotation, with located problems; and back.

:func:`build_value` turns a node into a value of a field's annotation (numbers,
strings, literals, lists, mappings, dataclasses) and records each problem in the
document with its line; :func:`to_plain` turns a dataclass back into plain data.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import itertools
import math
import re
import textwrap
import types
import typing
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Literal

import yaml

from cbp.errors import ConfigError, suggestion
from cbp.schema.reading import Node

if TYPE_CHECKING:
    from cbp.schema.document import Document

__all__ = [
    "INVALID",
    "MAX_MAGNITUDE",
    "Tagged",
    "build_value",
    "field_docs",
    "join_path",
    "key_nodes",
    "mapping_items",
    "node_at",
    "to_plain",
    "type_name",
    "value_node",
]


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


#: Largest magnitude of a number in a file: beyond it, squares and products of
#: positions, sizes and gains overflow. Integers have the same bound (counts
#: that size memory or loops have tighter ones of their own).
MAX_MAGNITUDE = 1e12


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


def build_value(doc: Document, tp: Any, node: Node | None, where: str) -> Any:
    """Build a value of annotation ``tp`` from ``node``; INVALID on a problem.

    Each problem is recorded in ``doc`` at ``where`` (a document path).
    """
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
        return build_value(doc, members[0], node, where)
    # Try each member on a scratch document state; keep the first that builds.
    for member in members:
        saved = len(doc.problems)
        value = build_value(doc, member, node, where)
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
        build_value(doc, item_tp, item, join_path(where, i))
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
    built = {
        k: build_value(doc, value_tp, v, join_path(where, k)) for k, v in items.items()
    }
    return INVALID if any(v is INVALID for v in built.values()) else built


@typing.runtime_checkable
class Tagged(typing.Protocol):
    """A section whose ``type:`` key names which of its variants it is.

    :meth:`variants` maps each type name to the dataclass (a subclass) that
    reads such a section: the section is built as the one its ``type`` names,
    with that one's keys, defaults and checks (a goal's kinds,
    :class:`cbp.goals.GoalSpec`).
    """

    @classmethod
    def variants(cls) -> Mapping[str, type]:
        """The dataclass of each variant, by type name."""
        ...


def _variant(
    doc: Document,
    variants: Mapping[str, type],
    items: dict[str, Node],
    node: Node | None,
    where: str,
) -> type | None:
    """The variant the section's ``type`` names; None (a problem recorded) if none."""
    kinds = Literal[tuple(variants)]  # type: ignore[valid-type]
    at = join_path(where, "type")
    if "type" not in items:
        doc.report(node, at, f"missing required key 'type' ({type_name(kinds)})")
        return None
    name = build_value(doc, kinds, items["type"], at)
    return None if name is INVALID else variants[name]


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
    if isinstance(cls, Tagged) and base is None:
        variants = cls.variants()
        if cls not in variants.values():
            variant = _variant(doc, variants, items, node, where)
            if variant is None:
                return INVALID
            cls = variant
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
                else build_value(doc, tp, items[name], path)
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


def node_at(root: Node | None, path: str) -> Node | None:
    """The node at a document path (``goal.function.position[1]``), or None."""
    node = root
    for key in re.findall(r"\[\d+\]|[^.\[\]]+", path):
        if not key.startswith("["):
            node = value_node(node, key)
        elif isinstance(node, yaml.SequenceNode) and int(key[1:-1]) < len(node.value):
            node = node.value[int(key[1:-1])]
        else:
            node = None
        if node is None:
            return None
    return node


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
