# SPDX-License-Identifier: Apache-2.0
"""Plugin registries: an explicit in-tree list, plus entry points and dotted paths.

A type name resolves, in order, to:

1. an in-tree plugin, listed explicitly in ``plugins/tasks/__init__.py`` or
   ``plugins/constraints/__init__.py``;
2. a dotted path ``"package.module:ClassName"``, imported normally or, failing that,
   from ``module.py`` in one of the search folders (the scenario file's folder);
3. a plugin of an installed distribution, declared under the entry point group
   ``cbp.tasks`` or ``cbp.constraints``.

Every class, whatever its source, was checked when Python defined it
(:meth:`cbp.plugin.Plugin.__init_subclass__`); the registry checks its kind.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import sys
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, Generic, TypeVar

from cbp.data import is_file
from cbp.errors import (
    ConfigError,
    PluginDefinitionError,
    UnknownPluginError,
    close_matches,
)
from cbp.plugin import Plugin

P = TypeVar("P", bound=Plugin[Any])


class Registry(Generic[P]):
    """A sorted, checked mapping from type name to plugin class, for one kind.

    Attributes:
        kind: ``"task"`` or ``"constraint"``.
        base: the class every entry must derive from.
        group: the entry point group searched for names not in the tree.
    """

    def __init__(self, kind: str, base: type[Any], classes: Sequence[type[P]]) -> None:
        """Check every class and index it by ``type_name``.

        Raises:
            TypeError: a class breaks the contract, or names are duplicated or the
                list is not sorted (these are programming errors of the framework).
        """
        self.kind = kind
        self.base = base
        self.group = f"cbp.{kind}s"
        self._classes: dict[str, type[P]] = {}
        for cls in classes:
            self.validate(cls)
            if cls.type_name in self._classes:
                raise TypeError(f"duplicate {kind} type name '{cls.type_name}'")
            self._classes[cls.type_name] = cls
        names = list(self._classes)
        if names != sorted(names):
            raise TypeError(f"the {kind} registry must be sorted by type name: {names}")

    def validate(self, cls: object) -> type[P]:
        """Check that ``cls`` is a concrete plugin class of this kind; return it.

        The contract itself is checked when the class is defined
        (:meth:`cbp.plugin.Plugin.__init_subclass__`); here only its kind.
        """
        where = getattr(cls, "__qualname__", repr(cls))
        if not (isinstance(cls, type) and issubclass(cls, self.base)):
            raise TypeError(
                f"{where} is not a {self.kind}: subclass cbp.{self.base.__name__}"
            )
        if not hasattr(cls, "type_name"):
            raise TypeError(
                f"{where} is a generic base, not a plugin: subclass it with "
                "concrete parameters"
            )
        return cls

    def names(self) -> list[str]:
        """In-tree type names, sorted."""
        return list(self._classes)

    def entry_point_names(self) -> list[str]:
        """Type names offered by installed distributions."""
        return sorted(
            ep.name for ep in importlib.metadata.entry_points(group=self.group)
        )

    def __iter__(self) -> Iterator[type[P]]:
        """Iterate over the in-tree classes, sorted by type name."""
        return iter(self._classes.values())

    def __len__(self) -> int:
        """Number of in-tree classes."""
        return len(self._classes)

    def __contains__(self, name: object) -> bool:
        """Whether ``name`` is an in-tree type name."""
        return name in self._classes

    def get(self, name: str, search_dirs: Iterable[Path] = ()) -> type[P]:
        """Resolve a type name, a dotted path or an entry point to a checked class.

        Raises:
            UnknownPluginError: nothing matches; the message lists every available
                name and the nearest one.
            ConfigError: a dotted path or entry point fails to import or is not a
                valid plugin of this kind.
        """
        cls = self._classes.get(name)
        if cls is not None:
            return cls
        if ":" in name:
            return self._check_loaded(name, _import_dotted(name, search_dirs))
        for ep in importlib.metadata.entry_points(group=self.group, name=name):
            try:
                loaded = ep.load()
            except Exception as exc:
                raise ConfigError(
                    f"{self.kind} type '{name}' from entry point {ep.value} failed to "
                    f"import: {type(exc).__name__}: {exc}"
                ) from exc
            return self._check_loaded(name, loaded)
        available = self.names() + self.entry_point_names()
        nearest = close_matches(name, available, n=1)
        hint = f"; did you mean '{nearest[0]}'?" if nearest else ""
        raise UnknownPluginError(
            f"unknown {self.kind} type '{name}'{hint} Available: "
            f"{', '.join(available)} (or a 'module:Class' path)."
        )

    def _check_loaded(self, name: str, loaded: object) -> type[P]:
        try:
            return self.validate(loaded)
        except TypeError as exc:
            raise ConfigError(f"{self.kind} type '{name}': {exc}") from exc

    def __repr__(self) -> str:
        """Kind and names."""
        return f"Registry({self.kind!r}, {self.names()})"


def _import_dotted(path: str, search_dirs: Iterable[Path]) -> object:
    module_name, _, attr = path.partition(":")
    if not module_name or not attr:
        raise ConfigError(f"'{path}' is not of the form 'module:ClassName'")
    module = None
    for folder in search_dirs:
        candidate = Path(folder) / (module_name.replace(".", "/") + ".py")
        if is_file(candidate):
            module = _import_file(module_name, candidate)
            break
    if module is None:
        try:
            module = importlib.import_module(module_name)
        except PluginDefinitionError as exc:
            raise ConfigError(str(exc)) from exc
        except ImportError as exc:
            raise ConfigError(
                f"cannot import module '{module_name}' of '{path}': {exc}"
            ) from exc
    try:
        return getattr(module, attr)
    except AttributeError:
        public = [n for n in dir(module) if not n.startswith("_")]
        nearest = close_matches(attr, public, n=1)
        hint = f"; did you mean '{nearest[0]}'?" if nearest else ""
        raise ConfigError(f"module '{module_name}' has no '{attr}'{hint}") from None


def _import_file(module_name: str, path: Path) -> object:
    key = f"cbp_user_plugins.{module_name}"
    cached = sys.modules.get(key)
    if cached is not None and getattr(cached, "__file__", None) == str(path):
        return cached
    spec = importlib.util.spec_from_file_location(key, path)
    if spec is None or spec.loader is None:
        raise ConfigError(f"cannot import plugin file {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[key] = module
    try:
        spec.loader.exec_module(module)
    except PluginDefinitionError as exc:
        del sys.modules[key]
        raise ConfigError(f"{exc} ({path})") from exc
    except Exception as exc:
        del sys.modules[key]
        raise ConfigError(
            f"plugin file {path} failed to import: {type(exc).__name__}: {exc}"
        ) from exc
    return module
