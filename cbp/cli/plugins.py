# SPDX-License-Identifier: Apache-2.0
"""``cbp plugins``: every plugin with its parameters, defaults and units."""

from __future__ import annotations

import argparse
import dataclasses
import typing

from cbp.cli.command import Command
from cbp.registry import Registry
from cbp.schema import type_name

__all__ = ["PLUGINS"]


def _plugins(args: argparse.Namespace) -> int:
    from cbp.plugins.constraints import CONSTRAINTS
    from cbp.plugins.tasks import TASKS
    from cbp.schema import field_docs

    registry: Registry[typing.Any]
    for registry in (TASKS, CONSTRAINTS):
        print(f"{registry.kind}s:")
        for cls in registry:
            print(f"  {cls.type_name}  [{cls.unit}]  default gain {cls.default_gain}")
            summary = (cls.__doc__ or "").strip().splitlines()[0]
            print(f"      {summary}")
            hints = typing.get_type_hints(cls.Params)
            docs = field_docs(cls.Params)
            for f in dataclasses.fields(cls.Params):
                kind = type_name(hints[f.name])
                print(f"      params.{f.name}: {kind}, {_default(f)}")
                if f.name in docs:
                    print(f"          {docs[f.name]}")
        extra = registry.entry_point_names()
        if extra:
            print(f"  from installed distributions: {', '.join(extra)}")
    return 0


def _default(f: dataclasses.Field[typing.Any]) -> str:
    """How the listing shows a parameter's default: ``default 0.1`` or ``required``."""
    if f.default is not dataclasses.MISSING:
        return f"default {f.default!r}"
    if f.default_factory is not dataclasses.MISSING:
        return f"default {f.default_factory()!r}"
    return "required"


PLUGINS = Command("plugins", "list every plugin with its parameters", _plugins)
