"""The importer registry (``inspector.data.importers.FORMATS``): one record per input format, the
only place an importer module is named, the source of ``inspector import``'s commands and of the
"no layout recognised" line."""

from __future__ import annotations

import ast
import inspect
import re
import shutil
from pathlib import Path

import pytest

import inspector
from inspector.cli import build_parser, main
from inspector.data.importers import FORMATS, format_named, no_layout_fits, recognised
from inspector.data.importers.in_memory import InMemory
from inspector.data.sources import open_sources
from inspector.errors import MAX_WHAT_CHARS, InspectorError

PACKAGE_DIR = Path(inspector.__file__).resolve().parent
IMPORTERS_DIR = PACKAGE_DIR / "data" / "importers"
REGISTRY = IMPORTERS_DIR / "__init__.py"
SERVED_NAME = "000001_pick_the_cube_26_01_02_03_04.mp4"  # NNNNNN_<prompt>_<time>.mp4, as the server names it


def family(fmt) -> set[str]:
    """The modules of a format: its importer module and those named after the format."""
    stem = fmt.name.replace("-", "_")
    return {p.stem for p in IMPORTERS_DIR.glob("*.py") if p.stem.startswith(stem)}


def imported_names(source: str) -> set[str]:
    """Every dotted name an ``import`` or ``from ... import`` of ``source`` mentions."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names |= {part for alias in node.names for part in alias.name.split(".")}
        elif isinstance(node, ast.ImportFrom):
            names |= set((node.module or "").split(".")) | {alias.name for alias in node.names}
    return names


def test_each_format_is_one_module_offering_the_five_functions():
    assert len({f.name for f in FORMATS}) == len(FORMATS)
    for fmt in FORMATS:
        module = fmt.module.lstrip(".")
        assert module in family(fmt), f"{fmt.name}: its module {module} is not named after the format"
        importer = fmt.importer
        for name in ("recognises", "describe", "format_description", "import_command", "load_in_memory"):
            assert callable(getattr(importer, name, None)), f"{module} lacks {name}"
        # one signature for all: what sources.py and info.py call
        assert list(inspect.signature(importer.load_in_memory).parameters) == ["src", "dataset"], module
        assert list(inspect.signature(importer.describe).parameters) == ["src", "calibration"], module
        options = inspect.signature(importer.import_command).parameters
        assert list(options)[:2] == ["src", "dest"] and "overwrite" in options, module


@pytest.mark.slow  # parses every module of the package
def test_an_importer_module_is_named_only_in_its_own_modules_and_the_registry():
    # a reference to a module: an import of it, a dotted or file path to it, a :mod: role
    families = {fmt.name: family(fmt) for fmt in FORMATS}
    assert all(f.module.lstrip(".") in families[f.name] for f in FORMATS)
    found = []
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        imported = imported_names(text)
        for modules in families.values():
            if path == REGISTRY or path.stem in modules:
                continue
            for module in modules:
                pattern = rf"(?:importers[./]|\bfrom\s+\.+|\bimport\s+|`\.){module}\b"
                found += [f"{path.relative_to(PACKAGE_DIR)}: {m.group(0)}" for m in re.finditer(pattern, text)]
                found += [f"{path.relative_to(PACKAGE_DIR)}: imports {module}"] if module in imported else []
    assert not found, "importer modules named outside the registry:\n" + "\n".join(found)


def test_the_import_commands_are_the_registry(tmp_path):
    parser = build_parser()
    for fmt in FORMATS:
        args = parser.parse_args(["import", fmt.name, str(tmp_path / "src"), "-o", str(tmp_path / "out")])
        assert args.format == fmt.name and args.func.__name__ == "_cmd_import"
    with pytest.raises(SystemExit):
        parser.parse_args(["import", "no-such-format", "x", "-o", "y"])


def test_the_no_layout_line_names_every_layout_whole(tmp_path, capsys):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "notes.txt").write_text("hello")
    err = no_layout_fits(tmp_path / "x")
    assert len(err.what) <= MAX_WHAT_CHARS and "characters in all" not in err.what
    for fmt in FORMATS:
        assert f"{fmt.title} ({fmt.hint})" in err.what
    assert "a session (session.json)" in err.what and "a LeRobot dataset" in err.what
    assert main(["info", str(tmp_path / "x")]) == 2
    out = capsys.readouterr().err
    assert out == f"error: {err}\n"


def test_a_parent_holding_one_layout_names_it(dreamzero_dir, tmp_path, capsys):
    """A server's working directory, its predictions one level down: the line says which to pass."""
    server = tmp_path / "server"
    (server / "video_pred_output").mkdir(parents=True)
    (server / "logs").mkdir()
    shutil.copy(dreamzero_dir / "demo" / "train_ep0" / "predicted_video.mp4", server / "video_pred_output" / SERVED_NAME)
    assert recognised(server) is None
    assert recognised(server / "video_pred_output") is format_named("dreamzero-served")
    with pytest.raises(InspectorError) as opened:
        open_sources([server])
    assert opened.value.what == ("no layout recognised; it holds one DreamZero served-predictions directory: "
                                 "video_pred_output/ — pass that")
    assert main(["info", str(server)]) == 2
    assert "video_pred_output/ — pass that" in capsys.readouterr().err
    # two recognised directories: which one is not for the line to guess
    (server / "eval").mkdir()
    (server / "eval" / "eval_info.json").write_text("{}")
    assert "known: " in no_layout_fits(server).what


def test_load_in_memory_returns_one_type_for_every_format(dreamzero_dir):
    fmt = recognised(dreamzero_dir / "demo")
    assert fmt is format_named("dreamzero-so101")
    loaded = fmt.importer.load_in_memory(dreamzero_dir / "demo")
    try:
        assert isinstance(loaded, InMemory) and (loaded.session / "session.json").is_file()
        assert loaded.errors == {}
    finally:
        loaded.handle.cleanup()
    assert all(inspect.signature(f.importer.load_in_memory).return_annotation in ("InMemory", InMemory)
               for f in FORMATS)


def test_a_groot_dreams_dump_is_never_loaded_as_a_session(tmp_path):
    fmt = format_named("groot-dreams")
    assert fmt is not None
    with pytest.raises(InspectorError, match="import it first: inspector import groot-dreams"):
        fmt.importer.load_in_memory(tmp_path)
