"""The package's shape: one subpackage per layer, no import circles, public faces that resolve.

The import graph is read with ``ast`` from the source, so it sees every import: at the top of a
module, inside a function, and under ``if TYPE_CHECKING:`` (a circle through type-only imports
still ties two modules together for whoever reads or moves them).
"""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

import inspector

PACKAGE_DIR = Path(inspector.__file__).resolve().parent
REPO = PACKAGE_DIR.parent

# Layers, lowest first: a module may import from its own layer and those below it, never above.
LAYERS = [
    {"errors", "units", "schema", "cache", "progress", "_lazy", "_files", "_signals", "stats"},
    {"robot"},
    {"data"},
    {"said"},
    {"outcomes"},
    {"eval"},
    {"analysis"},
    {"jobs"},
    {"rows"},
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


MAX_MODULE_LINES = 600


def test_no_module_is_over_600_lines() -> None:
    """A module stays small enough to read alone; a longer one is split along its seams."""
    long = {str(p.relative_to(PACKAGE_DIR)): n for p in PACKAGE_DIR.rglob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


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


# --- the map: docs/development.md's "Layout of the code" against the package ----------------------

MAP_DOC = REPO / "docs" / "development.md"
MAP_HEADING = "## Layout of the code"
MODULE_NAME = re.compile(r"(?<![\w./-])([\w./-]*\w\.py)(?![\w/])")  # errors.py, data/session.py
FOLDER_NAME = re.compile(r"(?<![\w./-])([A-Za-z_][\w-]*(?:/[\w-]+)*/)(?![\w])")  # stats/, importers/


def code_map() -> list[str]:
    """The lines of the map: the first fenced block under the "Layout of the code" heading."""
    text = MAP_DOC.read_text(encoding="utf-8")
    assert MAP_HEADING in text, f"{MAP_DOC} has no {MAP_HEADING!r} section"
    block = text.split(MAP_HEADING, 1)[1].split("```", 2)
    assert len(block) == 3, f"{MAP_DOC}: no fenced map under {MAP_HEADING!r}"
    return block[1].strip("\n").splitlines()


def map_floors() -> list[tuple[str, str]]:
    """The map's floors in order: ``(package, its text)`` for each package of ``inspector/`` (a line
    indented two spaces that starts with ``name/``, and the more indented lines under it), and
    ``("", text)`` for the lines naming modules at the package's top. Lines outside ``inspector/``
    (not indented) come as ``("/", text)``."""
    floors: list[tuple[str, str]] = []
    for line in code_map():
        indent = len(line) - len(line.lstrip(" "))
        first = line.split()[0] if line.split() else ""
        if indent == 0:
            floors.append(("/", line))
        elif indent == 2 and first.endswith("/"):
            floors.append((first.rstrip("/"), line))
        elif indent == 2:
            floors.append(("", line))
        else:
            assert floors, f"map line {line!r} belongs to no floor"
            floors[-1] = (floors[-1][0], floors[-1][1] + "\n" + line)
    return floors


def packages() -> list[str]:
    """The top-level packages of ``inspector/`` (a folder with an ``__init__.py``)."""
    return sorted(p.parent.name for p in PACKAGE_DIR.glob("*/__init__.py"))


def test_the_map_names_every_package_and_module() -> None:
    """Every package and every module file of ``inspector/`` is on the map, a module on its own
    package's floor (a subpackage's modules on its package's), so a newcomer finds each one there."""
    floors = map_floors()
    texts: dict[str, str] = {}
    for package, text in floors:
        texts[package] = texts.get(package, "") + "\n" + text
    missing = [f"{p}/" for p in packages() if p not in texts]
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        rel = path.relative_to(PACKAGE_DIR)
        floor = rel.parts[0] if len(rel.parts) > 1 else ""
        named = set(MODULE_NAME.findall(texts.get(floor, ""))) | set(FOLDER_NAME.findall(texts.get(floor, "")))
        if path.name == "__init__.py":
            if len(rel.parts) > 2 and f"{rel.parts[-2]}/" not in named:  # a subpackage: by its folder
                missing.append(str(rel.parent) + "/")
        elif path.name not in {Path(n).name for n in named}:
            missing.append(str(rel))
    assert not missing, f"not on the map in {MAP_DOC.name} ({MAP_HEADING}):\n" + "\n".join(missing)


def test_the_map_names_nothing_that_is_not_there() -> None:
    """Each module the map names, and each folder it lists (a line's first word), exists where the
    map puts it."""
    wrong = []
    for package, text in map_floors():
        if package == "/":  # outside the package: a path from the repository's root
            first = text.split()[0]
            if first != "inspector/" and not (REPO / first).exists():
                wrong.append(first)
            continue
        where = PACKAGE_DIR / package
        if package and not (where / "__init__.py").is_file():
            wrong.append(f"{package}/ (no such package)")
            continue
        below = {p.name for p in where.rglob("*")} if package else {p.name for p in where.iterdir()}
        listed = [w for line in text.splitlines() if (w := line.split()[0]).endswith("/")]
        for name in MODULE_NAME.findall(text) + listed:
            if "/" in name.rstrip("/"):  # a path: from the package, or from the repository's root
                if not ((where / name).exists() or (REPO / name).exists() or (PACKAGE_DIR / name).exists()):
                    wrong.append(f"{package or 'inspector'}: {name}")
            elif name.rstrip("/") not in below and name != f"{package}/":
                wrong.append(f"{package or 'inspector'}: {name}")
    assert not wrong, f"the map in {MAP_DOC.name} names what is not there:\n" + "\n".join(wrong)


def test_the_map_floors_follow_the_layers() -> None:
    """The map lists the packages lowest layer first, as ``LAYERS`` orders them (data flows down)."""
    order = []
    for package, text in map_floors():
        if package == "/":
            continue
        names = [package] if package else [Path(n).stem for n in MODULE_NAME.findall(text)
                                           if "/" not in n and (PACKAGE_DIR / n).is_file()]
        order += [(layer_of(f"inspector.{name}"), name) for name in names]
    out_of_order = [f"{b} (layer {lb}) after {a} (layer {la})" for (la, a), (lb, b) in zip(order, order[1:]) if lb < la]
    assert not out_of_order, "the map's floors are not in LAYERS order:\n" + "\n".join(out_of_order)
