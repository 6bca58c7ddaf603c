"""The shape of the package: no import cycle, and a numerics layer (``dynamics``) that
knows nothing about maglev (it imports no module outside itself but the package's
compilation helpers)."""

from __future__ import annotations

import ast
from pathlib import Path

import maglev_match

ROOT = Path(maglev_match.__file__).parent
# what the numerics layer may import from the package besides itself: the compilation
# helpers, and the results protocol its branch and point results derive from (Plottable:
# standard library only, it knows no model)
NUMERICS_ALLOWED = {"maglev_match.core.aot", "maglev_match.core.jax_setup",
                    "maglev_match.core.reprs", "maglev_match.core.results"}


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
    # a result's ``plot`` method is the presentation hook the API promises on every result
    # (``result.plot()``): it imports the figure module when called, after every module is
    # loaded, so it is neither a dependency of the numerics nor part of an import cycle
    skip |= {id(sub) for node in ast.walk(tree)
             if isinstance(node, ast.FunctionDef) and node.name == "plot"
             and "maglev_match.plots" in ast.unparse(node) for sub in ast.walk(node)}
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
