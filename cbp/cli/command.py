# SPDX-License-Identifier: Apache-2.0
"""A row of the command table, and the helpers several commands share."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

__all__ = [
    "EXTRAS",
    "Command",
    "Parsers",
    "add_set",
    "missing_extra",
    "positive_int",
    "read_overrides",
]

#: The modules each optional extra of pyproject.toml brings, by extra.
EXTRAS = {"viewer": ("viser", "yourdfpy")}


class Parsers(Protocol):
    """Where subcommands' parsers are added (``ArgumentParser.add_subparsers()``)."""

    def add_parser(
        self, name: str, *, help: str | None = ..., description: str | None = ...
    ) -> argparse.ArgumentParser:
        """A new subcommand's parser."""
        ...


def _no_arguments(parser: argparse.ArgumentParser) -> None:
    """A command without arguments."""


@dataclass(frozen=True)
class Command:
    """One subcommand of ``cbp``: its name, its arguments and what runs it.

    Attributes:
        name: as typed (``run``, ``robot-pairs``).
        help: the line ``cbp --help`` shows for it.
        handle: runs it on the parsed arguments; returns the exit status.
            None for a command that only groups ``subcommands``.
        arguments: adds its arguments to its parser.
        description: the text atop ``cbp NAME --help`` (default: none).
        subcommands: the commands under it (``robot init``), one required.
    """

    name: str
    help: str
    handle: Callable[[argparse.Namespace], int] | None
    arguments: Callable[[argparse.ArgumentParser], None] = _no_arguments
    description: str | None = None
    subcommands: tuple[Command, ...] = ()

    def add_to(self, parsers: Parsers) -> None:
        """Add this command's parser (and its subcommands') to ``parsers``."""
        parser = parsers.add_parser(
            self.name, help=self.help, description=self.description
        )
        self.arguments(parser)
        if self.handle is not None:
            parser.set_defaults(handle=self.handle)
        if self.subcommands:
            under = parser.add_subparsers(dest=f"{self.name}_command", required=True)
            for command in self.subcommands:
                command.add_to(under)


def add_set(parser: argparse.ArgumentParser, help_text: str) -> None:
    """The repeatable ``--set KEY=VALUE`` scenario override (read by read_overrides)."""
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help=help_text
    )


def read_overrides(items: Sequence[str]) -> dict[str, str] | None:
    """``KEY=VALUE`` pairs from the command line; None (and a message) if malformed."""
    overrides = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            print(f"expected KEY=VALUE, got {item!r}", file=sys.stderr)
            return None
        overrides[key.strip()] = value
    return overrides


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def missing_extra(command: str, extra: str) -> bool:
    """Say which extra to install when a module of ``extra`` cannot be imported."""
    import importlib

    for module in EXTRAS[extra]:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError:
            print(
                f"cbp {command} needs the {extra} extra ({module} is not "
                f"installed): pip install 'cbp[{extra}]'",
                file=sys.stderr,
            )
            return True
    return False
