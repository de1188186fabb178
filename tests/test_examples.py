"""The scripts in examples/ run as a user runs them, and say what their docstrings promise."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # the examples as processes

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"


def run_example(name: str, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    out = subprocess.run([sys.executable, str(EXAMPLES / name), *args], capture_output=True, text=True,
                         cwd=cwd, timeout=600)
    assert out.returncode == 0, out.stderr
    return out


def test_every_example_has_a_usage_docstring_and_main() -> None:
    scripts = sorted(EXAMPLES.glob("*.py"))
    assert len(scripts) >= 3
    for script in scripts:
        text = script.read_text(encoding="utf-8")
        assert "Usage::" in text and "def main(" in text and '__name__ == "__main__"' in text, script.name


def test_report_from_python_names_the_tempo_fault_worst(tmp_path: Path) -> None:
    out = run_example("report_from_python.py", cwd=tmp_path).stdout.splitlines()
    assert out[0].startswith("tempo_0.8x") and "tempo 0.80" in out[0]
    assert out[3].startswith("17 rollouts: chunk RMSE mean 4.716 deg")
    assert any(line.startswith("Autoregressive rollouts") for line in out)


@pytest.mark.slow
def test_evaluation_loop_writes_a_session_the_report_measures(tmp_path: Path) -> None:
    session = tmp_path / "eval"
    out = run_example("evaluation_loop.py", str(session), cwd=tmp_path).stdout
    assert "16 single-chunk samples" in out
    report = subprocess.run([sys.executable, "-m", "inspector", "report", str(session), "--json", "--jobs", "1"],
                            capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert report.returncode == 0, report.stderr
    rows = json.loads(report.stdout)["rollouts"]
    assert len(rows) == 16 and {r["kind"] for r in rows} == {"single_chunk"}
    # the stand-in model's bias grows linearly to 3 deg over 24 steps on every joint
    bias = np.linspace(0.0, 3.0, 24)
    expected_rmse = float(np.sqrt(np.mean(bias ** 2)))
    assert all(abs(r["rmse_deg"] - expected_rmse) < 1e-9 for r in rows)


@pytest.mark.slow
def test_export_rollout_writes_a_recording(tmp_path: Path) -> None:
    rrd = tmp_path / "tempo.rrd"
    out = run_example("export_rollout.py", str(rrd), cwd=tmp_path).stdout
    assert "tempo_0.8x: 49 chunks, tempo 0.80" in out
    assert rrd.stat().st_size > 1_000_000
    from test_export import rrd_verify

    rrd_verify(rrd)
