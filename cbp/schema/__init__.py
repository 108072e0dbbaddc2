# SPDX-License-Identifier: Apache-2.0
"""Strict YAML to frozen-dataclass loading with located, collected error messages.

A schema is a dataclass. Its fields' annotations say what a YAML value may be:
``float``, ``int``, ``str``, ``bool``, ``Literal[...]``, ``X | None``, ``tuple[float,
...]`` (any length), ``tuple[float, float, float]`` (fixed length), ``list[X]``,
``dict[str, X]``, another dataclass, or ``Any`` (taken as parsed). Unknown keys,
missing required keys, wrong types and wrong lengths are all reported, each with the
file, the line, the path in the document and the closest valid choice, and all the
problems of one file are reported together (:class:`~cbp.errors.ScenarioError`).

By concern: :mod:`.reading` turns text into a node tree safely,
:mod:`.document` holds a file's tree and problems (includes, ``--set``), and
:mod:`.values` builds values from nodes by their annotation.
"""

from cbp.schema.document import Document, from_plain, load_file
from cbp.schema.reading import MAX_DEPTH, MAX_VALUES, Loader, Node, check_tree
from cbp.schema.values import (
    INVALID,
    MAX_MAGNITUDE,
    Tagged,
    field_docs,
    join_path,
    key_nodes,
    mapping_items,
    node_at,
    to_plain,
    type_name,
    value_node,
)

__all__ = [
    "INVALID",
    "MAX_DEPTH",
    "MAX_MAGNITUDE",
    "MAX_VALUES",
    "Document",
    "Loader",
    "Node",
    "Tagged",
    "check_tree",
    "field_docs",
    "from_plain",
    "join_path",
    "key_nodes",
    "load_file",
    "mapping_items",
    "node_at",
    "to_plain",
    "type_name",
    "value_node",
]
