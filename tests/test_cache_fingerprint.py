"""The metrics cache's code fingerprint comes from modules found by import: a module renamed or
removed fails it loudly (never drops out of it, leaving stale entries readable), and a change to
a fingerprinted module's source changes it."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

import inspector
from inspector.cache import IMPORT_MODULES, METRIC_MODULES, code_fingerprint, fingerprinted_files

PACKAGE_DIR = Path(inspector.__file__).resolve().parent


@pytest.fixture
def scratch_package(tmp_path, monkeypatch):
    """A package ``fp_scratch`` with two modules, importable from ``tmp_path``; the fingerprint's
    memo and the package's import are dropped before and after, so each test sees its own files."""
    root = tmp_path / "fp_scratch"
    root.mkdir()
    (root / "__init__.py").write_text('"""scratch"""\n')
    (root / "speed.py").write_text("def speed(d, t):\n    return d / t\n")
    (root / "gain.py").write_text("GAIN = 2.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    forget_scratch()
    yield root
    forget_scratch()


def forget_scratch() -> None:
    for name in [m for m in sys.modules if m.split(".")[0] == "fp_scratch"]:
        del sys.modules[name]  # find_spec imported the package from another test's folder
    importlib.invalidate_caches()
    code_fingerprint.cache_clear()


def test_every_fingerprinted_module_exists_and_is_read():
    for modules in (METRIC_MODULES, IMPORT_MODULES):
        files = fingerprinted_files(modules)
        assert all(path.is_file() for _, path in files)
        assert len(code_fingerprint(modules)) == 16
    importers = {p for _, p in fingerprinted_files(IMPORT_MODULES)}
    assert importers >= set((PACKAGE_DIR / "data" / "importers").glob("*.py"))  # a new importer joins by itself
    assert PACKAGE_DIR / "rows" / "rollout.py" in {p for _, p in fingerprinted_files(METRIC_MODULES)}


def test_a_missing_module_fails_the_fingerprint_loudly(scratch_package):
    with pytest.raises(ModuleNotFoundError, match="fp_scratch.nothing_here"):
        code_fingerprint(("fp_scratch.speed", "fp_scratch.nothing_here"))
    with pytest.raises(ModuleNotFoundError, match="fp_gone.rows"):  # its package is gone too
        code_fingerprint(("fp_gone.rows",))


def test_renaming_a_fingerprinted_module_fails_the_fingerprint(scratch_package):
    modules = ("fp_scratch.speed", "fp_scratch.gain")
    assert code_fingerprint(modules)
    (scratch_package / "speed.py").rename(scratch_package / "velocity.py")
    importlib.invalidate_caches()
    code_fingerprint.cache_clear()
    with pytest.raises(ModuleNotFoundError, match="fp_scratch.speed"):
        code_fingerprint(modules)


def test_a_source_change_changes_the_fingerprint(scratch_package):
    modules = ("fp_scratch.speed", "fp_scratch.gain")
    before = code_fingerprint(modules)
    code_fingerprint.cache_clear()
    assert code_fingerprint(modules) == before  # the same source: the same fingerprint
    (scratch_package / "speed.py").write_text("def speed(d, t):\n    return d / t / 2\n")
    code_fingerprint.cache_clear()
    changed = code_fingerprint(modules)
    assert changed != before
    assert code_fingerprint(("fp_scratch.gain", "fp_scratch.speed")) != changed  # which file holds what counts


def test_a_package_entry_covers_every_module_in_it(scratch_package):
    before = code_fingerprint(("fp_scratch",))
    (scratch_package / "extra.py").write_text("EXTRA = 1\n")
    code_fingerprint.cache_clear()
    assert code_fingerprint(("fp_scratch",)) != before
    names = [name for name, _ in fingerprinted_files(("fp_scratch",))]
    assert names == ["fp_scratch/__init__.py", "fp_scratch/extra.py", "fp_scratch/gain.py", "fp_scratch/speed.py"]
