"""The wheel holds every package and data file: built here, installed into a fresh venv, run there."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

REPO = Path(__file__).resolve().parents[1]


def test_every_package_is_listed_for_the_wheel() -> None:
    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    on_disk = {".".join(p.parent.relative_to(REPO).parts) for p in (REPO / "inspector").rglob("__init__.py")}
    assert on_disk <= listed, f"not in pyproject.toml's packages: {sorted(on_disk - listed)}"


@pytest.mark.slow
def test_the_installed_wheel_reports_the_demo(tmp_path: Path) -> None:
    wheel_dir = tmp_path / "wheel"
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                            "-w", str(wheel_dir), str(REPO)], capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr
    wheel = next(wheel_dir.glob("inspector-*.whl"))
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=False)
    python = env_dir / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    # the dependencies come from this environment (listed as a plain path: its own .pth files,
    # among them the editable install of this checkout, are not read), inspector from the wheel
    (site / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    install = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "-q",
                              str(wheel)], capture_output=True, text=True, timeout=600)
    assert install.returncode == 0, install.stderr
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    where = subprocess.run([str(python), "-c", "import inspector; print(inspector.__file__)"], capture_output=True,
                           text=True, cwd=tmp_path, env=env, check=True).stdout
    assert where.startswith(str(site)), where
    demo = str(REPO / "sessions" / "demo")
    installed = subprocess.run([str(env_dir / "bin" / "inspector"), "report", demo, "--json", "--jobs", "1"],
                               capture_output=True, text=True, cwd=tmp_path, env=env, timeout=600)
    assert installed.returncode == 0, installed.stderr
    here = subprocess.run([sys.executable, "-m", "inspector", "report", demo, "--json", "--jobs", "1"],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=600)
    assert installed.stdout == here.stdout
    page = tmp_path / "page.html"  # the report's assets (styles, script) are package data
    html = subprocess.run([str(env_dir / "bin" / "inspector"), "report", demo, "--html", str(page), "--jobs", "1"],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=600)
    assert html.returncode == 0, html.stderr
    assert "<script" in page.read_text(encoding="utf-8")
