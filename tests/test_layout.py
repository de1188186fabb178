"""The package's shape: one subpackage per layer, no import circles, public faces that resolve.

The import graph is read with ``ast`` from the source, so it sees every import: at the top of a
module, inside a function, and under ``if TYPE_CHECKING:`` (a circle through type-only imports
still ties two modules together for whoever reads or moves them).
"""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

import inspector

PACKAGE_DIR = Path(inspector.__file__).resolve().parent
REPO = PACKAGE_DIR.parent

# Layers, lowest first: a module may import from its own layer and those below it, never above.
LAYERS = [
    {"errors", "units", "schema", "cache", "progress", "_lazy", "_files", "_signals", "_flag_values", "stats"},
    {"robot"},
    {"data"},
    {"outcomes"},
    {"eval"},
    {"analysis"},
    {"jobs"},
    {"report"},
    {"export"},
    {"app"},
    {"demo"},
    {"cli", "__main__"},
]


def module_name(path: Path) -> str:
    parts = ("inspector", *path.relative_to(PACKAGE_DIR).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in PACKAGE_DIR.rglob("*.py")}


def source_module(name: str, path: Path, node: ast.ImportFrom) -> str:
    """The absolute module a ``from ... import`` in module ``name`` (file ``path``) reads from."""
    if not node.level:
        return node.module or ""
    base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imported_modules(name: str, path: Path, known: set[str]) -> set[str]:
    """The package's own modules that ``name`` imports, wherever in the file."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = source_module(name, path, node)
            # `from pkg import mod` imports the module; `from mod import name` the module itself
            targets = [f"{module}.{alias.name}" if f"{module}.{alias.name}" in known else module
                       for alias in node.names]
        for target in targets:
            while target not in known and "." in target:
                target = target.rsplit(".", 1)[0]
            if target in known and target != name:
                found.add(target)
    return found


def import_graph() -> dict[str, set[str]]:
    mods = modules()
    return {name: imported_modules(name, path, set(mods)) for name, path in mods.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle, as the list of modules around it, or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if nxt.startswith(node + "."):  # a package importing its own submodules is its face
                continue
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def layer_of(name: str) -> int:
    top = name.split(".")[1] if "." in name else ""
    for i, layer in enumerate(LAYERS):
        if top in layer:
            return i
    raise AssertionError(f"{name} is in no layer; add its package to LAYERS")


@pytest.mark.slow
def test_no_import_cycles() -> None:
    assert find_cycle(import_graph()) is None, " -> ".join(find_cycle(import_graph()) or [])


def test_the_cycle_finder_finds_a_circle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}
    assert find_cycle(graph) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_imports_run_down_the_layers() -> None:
    upward = [f"{name} -> {target}" for name, targets in import_graph().items() if name != "inspector"
              for target in targets if target != "inspector" and layer_of(target) > layer_of(name)]
    assert not upward, "imports from a higher layer:\n" + "\n".join(sorted(upward))


def test_no_private_name_crosses_a_package() -> None:
    """``from .x import _name`` only within one package; another package goes through its face."""
    crossings = []
    for name, path in modules().items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom):
                continue
            source = source_module(name, path, node)
            source_package = source if (PACKAGE_DIR.parent / source.replace(".", "/")).is_dir() \
                else source.rsplit(".", 1)[0]
            if not source.startswith("inspector") or source_package == package:
                continue
            crossings += [f"{name}: from {source} import {alias.name}" for alias in node.names
                          if alias.name.startswith("_") and alias.name != "__version__"]
    assert not crossings, "\n".join(crossings)


def test_few_modules_at_the_top() -> None:
    top = sorted(p.name for p in PACKAGE_DIR.glob("*.py"))
    assert len(top) <= 10, top


@pytest.mark.parametrize("package", sorted({m.rsplit(".", 1)[0] for m in modules() if m.count(".") >= 2}
                                           | {"inspector"}))
def test_every_public_name_resolves(package: str) -> None:
    """A package's face (``__all__``) names only what it really has, and ``dir()`` shows it."""
    module = importlib.import_module(package)
    names = getattr(module, "__all__", [])
    assert names, f"{package} declares no __all__"
    for public in names:
        assert getattr(module, public) is not None, f"{package}.{public}"
        assert public in dir(module)


@pytest.mark.slow
def test_top_level_imports_stay_light() -> None:
    """``import inspector`` loads nothing heavy; names load on first use (``inspector info`` never
    pays for rerun, viser or torch)."""
    code = ("import sys, inspector; inspector.Session; "
            "print(','.join(m for m in ('rerun', 'viser', 'torch', 'inspector.analysis.timeline') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.strip() == ""
