# SPDX-License-Identifier: Apache-2.0
"""YAML text to a node tree, safely: the limits, the loader and the tree's checks.

Only plain values are read (no custom tags, no merge key), YAML 1.2's numbers are
numbers, and a tree too deep or too large once aliases are expanded is refused,
each problem with its line, before anything is built from it.
"""

from __future__ import annotations

import datetime
import re
from typing import TYPE_CHECKING

import yaml

from cbp.errors import ScenarioError

if TYPE_CHECKING:
    from cbp.schema.document import Document

__all__ = [
    "MAX_DEPTH",
    "MAX_VALUES",
    "Loader",
    "Node",
    "check_tree",
    "compose",
    "copy_tree",
]

Node = yaml.Node

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


def compose(text: str, name: str) -> Node | None:
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


def copy_tree(node: Node | None, copies: dict[int, Node]) -> Node | None:
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
            (copy_tree(k, copies), copy_tree(v, copies)) for k, v in node.value
        ]
    else:
        copy = yaml.SequenceNode(node.tag, [], node.start_mark, node.end_mark)
        copies[id(node)] = copy
        copy.value = [copy_tree(v, copies) for v in node.value]
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
