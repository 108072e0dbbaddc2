"""The layering holds: no import cycle, no private name across modules, light import.

No import cycle in ``cbp`` between modules (imports at run time) or between
packages (every import: at run time, inside functions, and under ``if
TYPE_CHECKING:``, names re-exported by a package followed to the module that
defines them), no private name of one module used by another, the scenario
package imports no executor, loading a scenario imports no simulator, and
``import cbp`` stays light.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ("cbp", "benchmarks")  # cbp/plugins links to plugins/


def _modules(package: str) -> dict[str, Path]:
    """Dotted module name -> file, for every module of ``package``.

    Linked folders are followed (``cbp/plugins`` links to ``plugins/``).
    """
    out = {}
    paths = [
        Path(folder, name)
        for folder, _, names in os.walk(ROOT / package, followlinks=True)
        for name in names
        if name.endswith(".py")
    ]
    for path in sorted(paths):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _imports(
    path: Path, type_checking: bool = False
) -> list[tuple[int, str, list[str]]]:
    """(line, module, names) of every import.

    Those under ``if TYPE_CHECKING:`` only when ``type_checking``.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if (
            not type_checking
            and isinstance(node, ast.If)
            and "TYPE_CHECKING" in ast.unparse(node.test)
        ):
            skipped |= {id(n) for child in node.body for n in ast.walk(child)}
    found = []
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.append((node.lineno, node.module, [a.name for a in node.names]))
    return found


def _edges(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the cbp modules it imports (a submodule imports its packages)."""
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, path in modules.items():
        for _, module, names in _imports(path):
            targets = [f"{module}.{n}" for n in names if f"{module}.{n}" in modules]
            targets.append(module)
            for target in targets:
                parts = target.split(".")
                for k in range(1, len(parts) + 1):
                    prefix = ".".join(parts[:k])
                    if prefix in modules and prefix != name:
                        graph[name].add(prefix)
    return graph


def _reexports(modules: dict[str, Path]) -> dict[tuple[str, str], str]:
    """(package, name) -> the module a package's ``__init__`` takes ``name`` from."""
    out = {}
    for package, path in modules.items():
        if path.name != "__init__.py":
            continue
        for _, module, names in _imports(path, type_checking=True):
            for name in names:
                out[(package, name)] = module
    return out


def _defining_module(
    module: str, name: str, modules: dict[str, Path], reexports: dict
) -> str:
    """The module ``from module import name`` reaches.

    A submodule, the module a package re-exports ``name`` from (followed
    through packages), or ``module`` itself.
    """
    seen = set()
    while (module, name) in reexports and (module, name) not in seen:
        seen.add((module, name))
        module = reexports[(module, name)]
    sub = f"{module}.{name}"
    return sub if sub in modules else module


def _unit(module: str) -> str | None:
    """The package (or top-level module) of ``cbp`` that ``module`` belongs to."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "cbp" and len(parts) > 1 else None


def _package_graph() -> dict[str, set[str]]:
    """Package -> the packages it imports, by every import there is."""
    modules = _modules("cbp")
    reexports = _reexports(modules)
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        unit = _unit(name)
        if unit is None:
            continue
        targets = graph.setdefault(unit, set())
        for _, module, names in _imports(path, type_checking=True):
            for target in [
                _defining_module(module, n, modules, reexports) for n in names
            ] or [module]:
                other = _unit(target)
                if other is not None and other != unit:
                    targets.add(other)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle_in_cbp() -> None:
    """No set of cbp modules imports itself round, lazily or not."""
    modules = _modules("cbp")
    graph = _edges(modules)
    # A package's __init__ re-exporting its submodules is not a layer of its own:
    # a submodule importing a sibling through it is the only cycle that matters.
    for package in [m for m, p in modules.items() if p.name == "__init__.py"]:
        for sub in list(graph[package]):
            if sub.startswith(package + "."):
                graph[package].discard(sub)
    assert _cycles(graph) == []


def test_no_import_cycle_between_packages() -> None:
    """No set of cbp packages imports itself round, counting every import.

    Type-checking imports and names re-exported by a package count: a loop
    between packages is a loop whether or not Python runs it.
    """
    graph = _package_graph()
    loops = _cycles(graph)
    assert loops == [], [
        f"{a} -> {b}" for loop in loops for a in loop for b in graph[a] if b in loop
    ]


def test_the_scenario_package_imports_no_executor() -> None:
    """The scenario is data: no module of cbp/scenario/ imports cbp.executors."""
    graph = _package_graph()
    assert "cbp.executors" not in graph["cbp.scenario"]
    assert "cbp.run" not in graph["cbp.scenario"]


#: What reports a run to people: formatting, figures, progress bars.
REPORTING = ("cbp.report", "cbp.metrics", "cbp.story", "cbp.plots", "cbp.progress")


def test_the_control_loop_imports_no_reporting() -> None:
    """Executors and the run layer tell their log; the command line formats it."""
    modules = _modules("cbp")
    for name, path in modules.items():
        if not name.startswith(("cbp.executors", "cbp.run")):
            continue
        for line, module, names in _imports(path, type_checking=True):
            targets = [module, *(f"{module}.{n}" for n in names)]
            assert not any(t.startswith(REPORTING) for t in targets), (
                f"{path.relative_to(ROOT)}:{line} imports {module}"
            )


def test_the_world_model_does_not_import_the_simulator() -> None:
    """Perception and collision import no cbp.sim; loading a scenario no simulator."""
    graph = _package_graph()
    assert "cbp.sim" not in graph["cbp.perception"]
    assert "cbp.sim" not in graph["cbp.collision"]
    assert "cbp.sim" not in graph["cbp.scenario"]
    code = (
        "import sys; from cbp.scenario import load_scenario; "
        f"load_scenario({str(ROOT / 'scenarios' / 'cat_boards.yaml')!r}, "
        "overrides={'simulator': 'mujoco'}); "
        "print(sorted(m for m in sys.modules "
        "if m.split('.')[0] in ('pybullet', 'mujoco') "
        "or m.startswith(('cbp.sim', 'cbp.executors', 'cbp.run'))))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert done.stdout.strip() == "[]"


def test_no_private_name_crosses_a_module() -> None:
    """No library or benchmark module imports or reads another's private names."""
    problems = []
    for package in LIBRARY:
        for path in _modules(package).values():
            for line, module, names in _imports(path):
                private = [n for n in names if n.startswith("_") and n != "__version__"]
                hidden = [
                    p
                    for p in module.split(".")
                    if p.startswith("_") and not p.startswith("__")
                ]
                if private or hidden:
                    problems.append(f"{path.relative_to(ROOT)}:{line}: {module}")
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if (
                    isinstance(node, ast.Attribute)
                    and node.attr.startswith("_")
                    and not node.attr.startswith("__")
                    and not (
                        isinstance(node.value, ast.Name)
                        and node.value.id in ("self", "cls")
                    )
                ):
                    where = f"{path.relative_to(ROOT)}:{node.lineno}"
                    problems.append(f"{where}: .{node.attr}")
    assert problems == []


def test_importing_the_plugin_contract_stays_light() -> None:
    """``import cbp.plugin`` loads no collision, scenario, solver or QP module.

    (pinocchio itself imports coal, so coal is not on the list.)
    """
    code = (
        "import sys, cbp.plugin, cbp; "
        "heavy = sorted(m for m in sys.modules if m.split('.')[0] in "
        "('trimesh', 'numba', 'cvxpy', 'pybullet', 'ompl', 'matplotlib') "
        "or m in ('cbp.scenario', 'cbp.qp', 'cbp.collision', 'cbp.engine')); "
        "print(heavy)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert done.stdout.strip() == "[]"
