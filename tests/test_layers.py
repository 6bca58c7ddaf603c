"""The shape of the package, read from every import (those inside functions too): no import
cycle; the layers core < dynamics < maglev < analyses < api < plots, present < cli, each
importing only from its own layer and those below; a numerics layer (``dynamics``) that
knows nothing about maglev; a command line that reaches the computations through the API
only; no private name imported across modules; and no import by a name in a string but the
figure plug-in and the documented lazy and deprecated names (docs/architecture.md)."""

from __future__ import annotations

import ast
from pathlib import Path

import maglev_match

ROOT = Path(maglev_match.__file__).parent
# what the numerics layer may import from the package besides itself: the compilation
# helpers, the thread limits and the stop point of work run beside other work, and the
# results protocol its branch and point results derive from (Plottable: standard library
# only, it knows no model)
NUMERICS_ALLOWED = {"maglev_match.core.aot", "maglev_match.core.jax_setup",
                    "maglev_match.core.reprs", "maglev_match.core.results",
                    "maglev_match.core.threads", "maglev_match.core.beside"}


def _modules() -> dict[str, Path]:
    out = {}
    for f in ROOT.rglob("*.py"):
        parts = f.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = f
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Package modules imported by one module, at any depth (inside functions too), except
    under ``if TYPE_CHECKING:`` and the package root itself (the lazy facade that only
    gives ``__version__`` and names loaded on first use)."""
    tree = ast.parse(path.read_text())
    skip = {id(sub) for node in ast.walk(tree) if isinstance(node, ast.If)
            and "TYPE_CHECKING" in ast.unparse(node.test) for sub in ast.walk(node)}
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = pkg.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + ([base] if base else []))
            if base.startswith("maglev_match"):
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    found.add(sub if sub in modules else base)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("maglev_match"))
    return {m for m in found if m in modules and m not in (name, "maglev_match")}


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def test_no_import_cycle_in_the_package():
    graph = _graph()
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    cycles: list[list[str]] = []

    def visit(v: str, path: list[str]) -> None:
        state[v] = 1
        for w in sorted(graph[v]):
            if state.get(w) == 1:
                cycles.append(path[path.index(w):] + [w])
            elif w not in state:
                visit(w, path + [w])
        state[v] = 2

    for v in sorted(graph):
        if v not in state:
            visit(v, [v])
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_the_numerics_layer_imports_nothing_about_maglev():
    graph = _graph()
    numerics = {m for m in graph if m.startswith("maglev_match.dynamics")}
    assert "maglev_match.dynamics.cycles" in numerics
    outside = {m: sorted(t for t in graph[m] if t not in numerics | NUMERICS_ALLOWED)
               for m in numerics}
    assert not any(outside.values()), {m: t for m, t in outside.items() if t}


#: the layers, lowest first; a module may import from its own layer and those below
LAYERS = {"core": 0, "dynamics": 1, "maglev": 2, "analyses": 3, "api": 4, "plots": 5,
          "present": 5, "cli": 6, "explore": 6}
TOP = 7  # the package root (the lazy facade), __main__ and the old-path finder


def layer(module: str) -> int:
    parts = module.split(".")
    return LAYERS.get(parts[1], TOP) if len(parts) > 1 else TOP


def test_layer_of_every_module_is_known():
    graph = _graph()
    unknown = sorted(m for m in graph if layer(m) == TOP and m not in (
        "maglev_match", "maglev_match.__main__", "maglev_match.legacy_paths"))
    assert not unknown, f"modules outside the layers: {unknown}"


def test_every_import_goes_down_the_layers():
    graph = _graph()
    upward = sorted(f"{m} -> {t}" for m, deps in graph.items() for t in deps
                    if layer(t) > layer(m))
    assert not upward, "imports up the layers: " + "; ".join(upward)


def test_the_layer_rule_would_catch_an_upward_import():
    # the rule itself: an analysis importing the API or a figure module goes up
    assert layer("maglev_match.api.hopf") > layer("maglev_match.analyses.critical")
    assert layer("maglev_match.plots.maps") > layer("maglev_match.api.maps")
    assert layer("maglev_match.cli.common") > layer("maglev_match.present.documents")
    assert layer("maglev_match.core.params") < layer("maglev_match.dynamics.hopf")


#: what the command line may import outside itself: the API, the figures and documents,
#: the foundation (errors, parameters, units, files, options, checkpoints) and the light
#: catalogue of model names; never an analysis, a model or the numerics directly
CLI_MAY_IMPORT = ("maglev_match.api", "maglev_match.plots", "maglev_match.present",
                  "maglev_match.core", "maglev_match.maglev.catalog", "maglev_match.cli")


def test_the_command_line_reaches_the_computations_through_the_api_only():
    # the explorer (a layer beside the command line) follows the same rule
    graph = _graph()
    direct = sorted(f"{m} -> {t}" for m, deps in graph.items()
                    if m.startswith(("maglev_match.cli", "maglev_match.explore")) for t in deps
                    if not t.startswith((*CLI_MAY_IMPORT, "maglev_match.explore")))
    assert not direct, "the CLI imports past the API: " + "; ".join(direct)


def test_no_private_name_is_imported_from_another_module():
    modules = _modules()
    found = []
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                    "maglev_match") and node.level == 0:
                found += [f"{name}: from {node.module} import {a.name}" for a in node.names
                          if a.name.startswith("_") and not a.name.startswith("__")]
    assert not found, "private names imported across modules: " + "; ".join(found)


#: the only modules that import a module named in a string: the results' figure plug-in
#: (core.results loads maglev_match.plots on the first figure), the lazy facades of the
#: package root and of the API (PEP 562; and api.study_report, deprecated), the old-path
#: finder, the command line's registry of commands and its background pre-import
STRING_IMPORTS = {"maglev_match.core.results", "maglev_match", "maglev_match.api",
                  "maglev_match.legacy_paths", "maglev_match.cli", "maglev_match.cli.common"}


def test_imports_by_name_only_where_documented():
    found = set()
    for name, path in _modules().items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                fn = ast.unparse(node.func)
                if fn.endswith("import_module") or fn == "__import__":
                    found.add(name)
    assert found <= STRING_IMPORTS, f"imports by name in {sorted(found - STRING_IMPORTS)}"


def test_no_model_is_chosen_by_its_name_in_the_analyses():
    # the analyses ask the maglev model object (MaglevModel), never compare a model's name
    found = []
    for name, path in _modules().items():
        if not name.startswith(("maglev_match.analyses", "maglev_match.dynamics",
                                "maglev_match.api")):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Compare) and any(
                    isinstance(c, ast.Constant) and c.value in ("unit", "vehicle")
                    for c in node.comparators + [node.left]):
                found.append(f"{name}:{node.lineno}")
    assert not found, "model chosen by name at " + ", ".join(found)


def test_no_file_over_800_lines():
    long = {name: n for name, path in _modules().items()
            if (n := len(path.read_text().splitlines())) > 800}
    assert not long, long


def test_no_public_api_name_is_also_an_api_module():
    # api.stability was once both a function and the module defining it: importing the
    # module replaced the function on the package, and `api.stability(...)` failed
    # depending on the order of imports
    from maglev_match import api

    modules = {p.stem for p in (ROOT / "api").glob("*.py") if p.stem != "__init__"}
    assert not modules & set(api.__all__), modules & set(api.__all__)
    assert not modules & set(api._NAMES)
