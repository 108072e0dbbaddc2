"""Reference pages generated from the code: the command line, the file schemas, plugins.

Pure functions returning Markdown, so that a test can check them without building
the site; ``pages.py`` beside this file writes them at build time (mkdocs-gen-files),
so the reference cannot go stale. Only public names of ``cbp`` are used, and the few
places that name modules are the constants below.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib
import inspect
import os
import re
import textwrap
import types
import typing
from collections.abc import Iterator
from typing import Any

import yaml

from cbp.schema import field_docs

#: The in-tree plugin registries, as ``module:attribute`` (what ``cbp plugins`` lists).
REGISTRIES = ("cbp.plugins.tasks:TASKS", "cbp.plugins.constraints:CONSTRAINTS")

#: Modules of the Python API reference, one page each: the stable public entry
#: points. Add a module here to document it.
API_MODULES = (
    "cbp",
    "cbp.plugin",
    "cbp.testing",
    "cbp.engine",
    "cbp.methods",
    "cbp.run",
    "cbp.robot",
    "cbp.state",
    "cbp.scenario",
    "cbp.registry",
    "cbp.qp",
    "cbp.solvers",
    "cbp.errors",
)

#: The keys of a task or constraint entry in a scenario (read by the loader, which
#: builds ``cbp.qp.Entry``; the plugin's own settings go under ``params``).
ENTRY_KEYS = (
    (
        "type",
        "a string",
        "required",
        "The plugin's type name (see the plugin "
        "catalogue), or ``module:ClassName`` of a plugin of your own.",
    ),
    (
        "name",
        "a string or null",
        "null",
        "Names the entry for ``--set`` paths, inputs and events.",
    ),
    (
        "priority",
        "one of 'soft', 'hard'",
        "tasks soft, constraints hard",
        "``soft``: a weighted cost term; ``hard``: a QP constraint.",
    ),
    (
        "weight",
        "a number or a list of numbers",
        "1.0",
        "Weight of a soft entry: one number, or one per row of the plugin.",
    ),
    (
        "gain",
        "a number",
        "the plugin's default gain",
        "k in [0, 1]: the fraction of the error removed per step.",
    ),
    (
        "params",
        "a mapping",
        "the plugin's defaults",
        "The plugin's parameters (see the plugin catalogue).",
    ),
)


def _rst_to_md(text: str) -> str:
    """Docstring markup as Markdown.

    ``code`` and :role:`name` become code spans, ``.. math::`` blocks text blocks.
    """
    out: list[str] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith(".. math::"):
            block = [line.split(".. math::", 1)[1].strip()]
            i += 1
            while i < len(lines) and (not lines[i].strip() or lines[i][:1] == " "):
                block.append(lines[i])
                i += 1
            body = textwrap.dedent("\n".join(block[1:])).strip("\n")
            math = "\n".join(part for part in (block[0], body) if part)
            out += ["```text", math, "```", ""]
            continue
        out.append(re.sub(r":[a-z]+:`~?([^`]+)`", r"`\1`", line).replace("``", "`"))
        i += 1
    return "\n".join(out)


def _cell(text: str) -> str:
    """Text safe inside a Markdown table cell."""
    return _rst_to_md(text).replace("|", "\\|").replace("\n", " ")


def _yaml_value(value: Any) -> str:
    """A default as it would be written in YAML."""
    from cbp.schema import to_plain

    plain = _short_floats(to_plain(value))
    text = yaml.safe_dump(plain, default_flow_style=True, width=1000).strip()
    return text.removesuffix("\n...").removesuffix("...").strip()


def _short_floats(value: Any) -> Any:
    """Floats to six significant digits (a period of 1/30 s reads 0.0333333)."""
    if isinstance(value, float):
        return float(f"{value:.6g}")
    if isinstance(value, list | tuple):
        return [_short_floats(v) for v in value]
    if isinstance(value, dict):
        return {k: _short_floats(v) for k, v in value.items()}
    return value


def _dataclasses_in(tp: Any) -> list[type]:
    """The dataclasses an annotation holds (``X``, ``X | None``, ``list[X]``...)."""
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return [tp]
    found: list[type] = []
    for arg in typing.get_args(tp):
        found += _dataclasses_in(arg)
    return found


def _suffix(tp: Any) -> str:
    """How a key path goes on into an annotation: ``[]`` (list), ``.NAME`` (map)."""
    origin = typing.get_origin(tp)
    if origin in (types.UnionType, typing.Union):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return _suffix(args[0]) if len(args) == 1 else ""
    if origin in (list, tuple):
        return "[]"
    if origin is dict:
        return ".NAME"
    return ""


def _anchor(path: str) -> str:
    """A heading id for a key path."""
    cleaned = "".join(c if c.isalnum() else "-" for c in path.lower())
    return "-".join(part for part in cleaned.split("-") if part) or "top"


@dataclasses.dataclass
class _Section:
    paths: list[str]
    cls: type
    #: Where the section's keys are in a file (a variant's: its section's).
    key_path: str
    #: The fields it lists (a variant's: those its tagged section has not).
    fields: list[dataclasses.Field[Any]]

    @property
    def path(self) -> str:
        return self.paths[0]


def _variants(cls: type) -> dict[str, type]:
    """A tagged section's variants by type name ({} for another section)."""
    from cbp.schema import Tagged

    if not isinstance(cls, Tagged):
        return {}
    variants = dict(cls.variants())
    return {} if cls in variants.values() else variants


def _sections(root: type) -> list[_Section]:
    """Every dataclass reachable from ``root``, depth first, with its key paths.

    A dataclass used in several places (the executors' ``timing``) is one section,
    at the first path it is met, that lists the others. A tagged section (the
    goal's kinds) is followed by a section per variant, ``goal (type: step)``,
    with the keys that variant adds.
    """
    out: dict[type, _Section] = {}

    def visit(cls: type, path: str, key_path: str, shown: set[str]) -> None:
        if cls in out:
            if path not in out[cls].paths:
                out[cls].paths.append(path)
            return
        fields = [f for f in dataclasses.fields(cls) if f.name not in shown]
        out[cls] = _Section([path], cls, key_path, fields)
        hints = typing.get_type_hints(cls)
        for f in fields:
            for inner in _dataclasses_in(hints[f.name]):
                key = f"{key_path}.{f.name}" if key_path else f.name
                key += _suffix(hints[f.name])
                visit(inner, key, key, set())
        own = {f.name for f in dataclasses.fields(cls)}
        for name, variant in _variants(cls).items():
            visit(variant, f"{path} (type: {name})", key_path, own)

    visit(root, "", "", set())
    return list(out.values())


def _default(f: dataclasses.Field[Any]) -> str:
    if f.default is not dataclasses.MISSING:
        return f"`{_yaml_value(f.default)}`"
    if f.default_factory is not dataclasses.MISSING:
        value = f.default_factory()
        if dataclasses.is_dataclass(value):
            return "(section)"
        return f"`{_yaml_value(value)}`"
    return "**required**"


def schema_fields(root: type) -> list[tuple[str, str]]:
    """Every (key path, field name) of a schema, for checks of the reference."""
    fields = []
    for section in _sections(root):
        for f in section.fields:
            fields.append((section.path, f.name))
    return fields


def schema_page(
    root: type,
    title: str,
    intro: str,
    extra: dict[str, str] | None = None,
    notes: dict[str, str] | None = None,
) -> str:
    """A page with one table per section of a file schema.

    Args:
        root: the schema's top dataclass.
        title: the page title.
        intro: Markdown after the title.
        extra: Markdown appended to the section of the given key path.
        notes: descriptions of fields that have no docstring, by key path
            (fields made at run time, as ``method``'s).
    """
    from cbp.schema import type_name

    extra = extra or {}
    notes = notes or {}
    lines = [f"# {title}", "", intro, ""]
    sections = _sections(root)
    anchors = {section.cls: _anchor(section.path) for section in sections}
    for section in sections:
        cls = section.cls
        heading = f"`{section.path}`" if section.path else "Top level"
        lines += [f"## {heading} {{#{anchors[cls]}}}", ""]
        if len(section.paths) > 1:
            also = ", ".join(f"`{p}`" for p in section.paths[1:])
            lines += [f"The same section is also read at {also}.", ""]
        doc = inspect.getdoc(cls) or ""
        if doc:
            lines += [_rst_to_md(doc), ""]
        lines += ["| Key | Type | Default | Description |", "|---|---|---|---|"]
        hints = typing.get_type_hints(cls)
        docs = field_docs(cls)
        variants = _variants(cls)
        for f in section.fields:
            tp = hints[f.name]
            if variants and f.name == "type":  # the names of the variants
                tp = typing.Literal[tuple(variants)]
            described = _cell(type_name(tp))
            inner = _dataclasses_in(tp)
            if inner:
                described = f"[{described}](#{anchors[inner[0]]})"
            key = f"{section.key_path}.{f.name}" if section.key_path else f.name
            doc = notes.get(key, docs.get(f.name, ""))
            lines.append(
                f"| `{f.name}` | {described} | {_cell(_default(f))} | {_cell(doc)} |"
            )
        lines.append("")
        if section.path in extra:
            lines += [extra[section.path], ""]
    return "\n".join(lines)


def scenario_page() -> str:
    """The scenario file reference, from :class:`cbp.scenario.ScenarioSpec`."""
    from cbp.methods import METHODS
    from cbp.scenario import ScenarioSpec

    entry = [
        "### Task and constraint entries {#entries}",
        "",
        "`tasks:` and `constraints:` are lists of entries; each is bound to a "
        "plugin from the [plugin catalogue](plugins.md).",
        "",
        "| Key | Type | Default | Description |",
        "|---|---|---|---|",
        *(
            f"| `{k}` | {_cell(t)} | {_cell(d)} | {_cell(x)} |"
            for k, t, d, x in ENTRY_KEYS
        ),
    ]
    methods = [
        "### Executors {#executors}",
        "",
        "| `method.name` | What it does |",
        "|---|---|",
        *(f"| `{n}` | {_cell(i.summary)} |" for n, i in METHODS.items()),
    ]
    intro = (
        "Generated from the schema's dataclasses (`cbp.scenario.ScenarioSpec` and "
        "the sections it holds) when the site is built. Units are in brackets. "
        "`cbp check FILE.yaml` validates a file; every problem is reported with its "
        "line, and any value can be overridden from the command line with "
        "`--set KEY=VALUE` (list items by index, name or type: "
        "`--set constraints.contact_normals.gain=0.5`). A file can `include:` "
        "others (a shipped configuration by name: `include: cat`); its own keys "
        "win."
    )
    notes = {"method.name": "The executor that runs the scenario (below)."}
    for name in METHODS:
        notes[f"method.{name}"] = f"Settings of the `{name}` executor."
    return schema_page(
        ScenarioSpec,
        "Scenario file",
        intro,
        extra={"": "\n".join(entry), "method": "\n".join(methods)},
        notes=notes,
    )


def robot_page() -> str:
    """The robot.yaml reference, from :class:`cbp.robot.RobotDescription`."""
    from cbp.robot import RobotDescription

    intro = (
        "A robot folder holds the URDF and `robot.yaml`, generated here from "
        "`cbp.robot.RobotDescription`. `cbp robot init URDF --out DIR` writes one "
        "and says what it assumed; `cbp robot-pairs NAME` suggests "
        "`collision.ignore_pairs`. A scenario names the folder under `robot.name` "
        "(relative to the scenario, or a shipped robot's name)."
    )
    return schema_page(RobotDescription, "robot.yaml", intro, {})


def input_profile_page() -> str:
    """The input profile reference, from :class:`cbp.teleop.profiles.InputProfile`."""
    from cbp.teleop.profiles import InputProfile

    intro = (
        "An input profile maps a gamepad's or a 6-DOF mouse's axes and buttons "
        "to what `cbp teleop` moves, generated here from "
        "`cbp.teleop.profiles.InputProfile`. `cbp teleop SCENARIO --device gamepad` "
        "uses the shipped `scenarios/input/gamepad.yaml` (`spacemouse` likewise); "
        "`--profile FILE` reads your own (`cbp examples` copies the shipped ones "
        "out to edit). Every problem is reported with its line. "
        "[Drive with a gamepad or a 6-DOF mouse](../howto/devices.md) is the guide."
    )
    return schema_page(InputProfile, "Input profile", intro, {})


def _registries() -> Iterator[Any]:
    for spec in REGISTRIES:
        module, _, attr = spec.partition(":")
        yield getattr(importlib.import_module(module), attr)


def plugin_classes() -> list[type]:
    """Every in-tree plugin class, tasks first."""
    return [cls for registry in _registries() for cls in registry]


def plugins_page() -> str:
    """The plugin catalogue: each registered plugin with its parameters."""
    from cbp.schema import type_name

    lines = [
        "# Plugin catalogue",
        "",
        "Generated from the in-tree registries when the site is built (what "
        "`cbp plugins` prints). An entry in a scenario names the plugin by its "
        "type name and sets its parameters under `params:` (see "
        "[the scenario file](scenario.md#entries)). Plugins of your own are "
        "named by `module:ClassName` or published under the entry point groups "
        "`cbp.tasks` and `cbp.constraints` ([write a plugin]"
        "(../howto/write-plugin.md)).",
        "",
    ]
    for registry in _registries():
        lines += [f"## {registry.kind.capitalize()}s", ""]
        for cls in registry:
            lines += [f"### `{cls.type_name}`", ""]
            lines += [
                f"Class `{cls.__module__}.{cls.__qualname__}`; unit `{cls.unit}`; "
                f"default gain {cls.default_gain}.",
                "",
                _rst_to_md(inspect.getdoc(cls) or ""),
                "",
            ]
            params = dataclasses.fields(cls.Params)
            if not params:
                lines += ["No parameters.", ""]
                continue
            lines += [
                "| Parameter | Type | Default | Description |",
                "|---|---|---|---|",
            ]
            hints = typing.get_type_hints(cls.Params)
            docs = field_docs(cls.Params)
            for f in params:
                lines.append(
                    f"| `{f.name}` | {_cell(type_name(hints[f.name]))} "
                    f"| {_cell(_default(f))} | {_cell(docs.get(f.name, ''))} |"
                )
            lines.append("")
    return "\n".join(lines)


def cli_parser() -> argparse.ArgumentParser:
    """The parser ``cbp`` builds (``cbp.cli.build_parser``)."""
    from cbp.cli import build_parser

    return build_parser()


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


@contextlib.contextmanager
def _columns(width: int) -> Iterator[None]:
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(width)
    try:
        yield
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


def cli_commands() -> list[str]:
    """Every command and subcommand, as typed (``run``, ``robot init``...)."""
    names = []

    def walk(parser: argparse.ArgumentParser, prefix: str) -> None:
        for name, sub in _subcommands(parser).items():
            names.append(f"{prefix}{name}")
            walk(sub, f"{prefix}{name} ")

    walk(cli_parser(), "")
    return names


def cli_page() -> str:
    """The command line reference: the help of ``cbp`` and of every command."""
    parser = cli_parser()
    lines = [
        "# Command line",
        "",
        "Generated from `cbp`'s argument parser (`cbp.cli`) when the site is "
        "built: the text `cbp COMMAND --help` prints.",
        "",
    ]
    helps: dict[str, str] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}

    with _columns(88):

        def walk(p: argparse.ArgumentParser, prefix: str, level: int) -> None:
            for name, sub in _subcommands(p).items():
                full = f"{prefix}{name}"
                lines.extend([f"{'#' * level} `cbp {full}`", ""])
                if name in helps and level == 2:
                    lines.extend([helps[name].capitalize() + ".", ""])
                lines.extend(["```text", sub.format_help().rstrip(), "```", ""])
                walk(sub, f"{full} ", level + 1)

        lines += ["```text", parser.format_help().rstrip(), "```", ""]
        walk(parser, "", 2)
    return "\n".join(lines)


def api_page() -> str:
    """The Python API page: mkdocstrings fills in each module of ``API_MODULES``.

    The top-level ``cbp`` only re-exports names, so its section is a table of
    them, each linked to where its module documents it.
    """
    import cbp

    lines = [
        "# Python API",
        "",
        "The public entry points, documented from their docstrings when the site "
        "is built.",
        "",
        "::: cbp",
        "    options:",
        "      members: false",
        "",
        "| Name | What it is |",
        "|---|---|",
    ]
    for name in sorted(cbp.__all__, key=str.lower):
        obj = getattr(cbp, name)
        public = _public_module(name, obj)
        documented = inspect.isclass(obj) or inspect.isfunction(obj)
        if public and documented:
            label = f"[`{name}`][{public}.{name}]"
            summary = (inspect.getdoc(obj) or "").split("\n\n")[0]
        else:
            label = f"`{name}`"
            summary = f"See `{public}`." if public else ""
        lines.append(f"| {label} | {_cell(summary)} |")
    lines.append("")
    for module in API_MODULES:
        if module != "cbp":
            lines += [f"::: {module}", ""]
    return "\n".join(lines)


def _public_module(name: str, obj: Any) -> str | None:
    """The documented module that gives ``name``.

    One that exports it in ``__all__`` (``cbp.scenario``, not its parts), else one
    that holds it.
    """
    modules = [importlib.import_module(m) for m in API_MODULES[1:]]
    for module in modules:
        if name in getattr(module, "__all__", ()):
            return module.__name__
    for module in modules:
        if getattr(module, name, None) is obj:
            return module.__name__
    return None
