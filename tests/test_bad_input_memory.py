"""Input of legitimate size that used to take memory growing with it: an outcomes file of
hundreds of thousands of rows, 75,000 votes between two sessions, a chain of 1,000 sessions, two
rollouts of 8,000 latents, a video-only rollout at the longest allowed. Each command runs as a
process (``test_bad_input_sizes.cli``: peak RSS from ``getrusage``) and stays far under 1.5 GB; the
outcomes reader is also checked in the test's process.

``benchmarks/hostile_memory.py`` runs the same commands at the documented limits themselves.
"""

from __future__ import annotations

import json
import shutil
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from test_bad_input_sizes import cli

from inspector.data.session import MAX_VIDEO_ONLY_STEPS, ROLLOUT_FILE, ROLLOUTS_DIR, SessionWriter, open_session
from inspector.outcomes import import_outcomes
from inspector.outcomes._import_file import MAX_UNMATCHED_LISTED

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from hostile_memory import _session, _write_votes  # noqa: E402  (the benchmark's inputs, built once)

# After the changes these commands peak at 120-440 MiB; before, at 1.3-3.9 GB.
PEAK_RSS_MIB = 700


# ----------------------------------------------------------------------------------------------
# Outcomes files: streamed


def test_an_outcomes_file_of_many_rows_is_matched_row_by_row(tmp_path):
    session = _session(tmp_path, tags=("r0", "r1"))
    path = tmp_path / "outcomes.jsonl"
    n_stray = 300_000
    with path.open("w") as f:
        f.write('{"tag": "r0", "success": false}\n')
        f.write('{"tag":"x"}\n' * n_stray)
        f.write('{"tag": "r0", "success": true, "note": "the later row wins"}\n')
    tracemalloc.start()
    try:
        done = import_outcomes(path, session)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # the file's bytes and text (3.6 MB each) and a row at a time; holding every row took ~150 MB
    assert peak < 30 * 2**20, peak
    assert (done.rows, done.rollouts, done.unmatched_rows) == (2, 1, n_stray)
    assert len(done.unmatched) == MAX_UNMATCHED_LISTED and done.unmatched[0].line == 2
    stored = json.loads(done.store.read_text())
    assert "the later row wins" in json.dumps(stored)


def test_outcomes_import_names_the_first_unmatched_rows_and_counts_the_rest(tmp_path):
    session = _session(tmp_path)
    path = tmp_path / "outcomes.jsonl"
    path.write_text('{"tag": "r0", "success": true}\n' + '{"tag": "gone"}\n' * 250)
    run = cli(tmp_path, "outcomes", "import", path, session)
    assert run.returncode == 0, run.stderr
    lines = run.stderr.splitlines()
    assert len(lines) == MAX_UNMATCHED_LISTED + 1
    assert lines[0] == f"warning: {path}: line 2: tag 'gone' matches no rollout"
    assert lines[-1] == f"warning: {path}: {250 - MAX_UNMATCHED_LISTED} more row(s) match no rollout"


# ----------------------------------------------------------------------------------------------
# Video-only rollouts: the limit is one the commands meet


def _video_only(root: Path, steps: int) -> Path:
    with SessionWriter.create(root / "s", model={"name": "s"}) as w:
        w.add_rollout("long", kind="autoregressive", actions=None, n_chunks=steps // 1000, horizon=1000,
                      executed_per_chunk=1000, frames_per_chunk=1, fps=5.0,
                      videos={"front": np.full((4, 32, 48, 3), 100, np.uint8)})
    return root / "s"


def test_a_video_only_rollout_one_chunk_past_the_limit_is_refused_naming_n_chunks(tmp_path):
    session = _video_only(tmp_path, MAX_VIDEO_ONLY_STEPS)
    assert open_session(session).rollouts["long"].n_chunks == MAX_VIDEO_ONLY_STEPS // 1000
    meta_path = session / ROLLOUTS_DIR / "long" / ROLLOUT_FILE
    meta = json.loads(meta_path.read_text())
    meta["n_chunks"] += 1
    meta_path.write_text(json.dumps(meta))
    errors = open_session(session).errors
    assert "n_chunks" in str(errors["long"]) and f"{MAX_VIDEO_ONLY_STEPS:,} steps" in str(errors["long"])


@pytest.mark.slow
@pytest.mark.parametrize("command", ["report", "export"])
def test_a_video_only_rollout_at_the_limit_reports_and_exports_in_bounded_memory(tmp_path, command):
    session = _video_only(tmp_path, MAX_VIDEO_ONLY_STEPS)
    extra = ["--json"] if command == "report" else ["-o", tmp_path / "out.rrd"]
    run = cli(tmp_path, command, *extra, "--no-cache", "--jobs", "1", session)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.peak_mib < PEAK_RSS_MIB, run.peak_mib  # 10,000,000 steps passed 3 GB


# ----------------------------------------------------------------------------------------------
# rank and latents


@pytest.mark.slow
def test_rank_of_75000_votes_between_two_sessions(tmp_path):
    roots = [_session(tmp_path, f"s{i}") for i in range(2)]
    answers = np.random.default_rng(0).choice(["a", "b", "tie"], size=75_000, p=[0.5, 0.4, 0.1])
    _write_votes(roots, [(0, 1, str(a)) for a in answers])
    run = cli(tmp_path, "rank", "--json", *roots)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.peak_mib < PEAK_RSS_MIB, run.peak_mib
    result = json.loads(run.stdout)
    assert result["votes"] == 75_000 and result["bootstrap"] == 2000
    top = result["ranking"][0]
    assert (top["session"], top["wins"] + top["losses"] + top["ties"]) == ("s0", 75_000)


@pytest.mark.slow
def test_rank_of_1000_sessions_in_a_chain(tmp_path):
    first = _session(tmp_path, "s0000")
    roots = [first]
    for i in range(1, 1000):  # copies of one session: writing 1,000 takes minutes
        roots.append(Path(shutil.copytree(first, tmp_path / f"s{i:04d}")).resolve())
    rng = np.random.default_rng(0)
    _write_votes(roots, [(i, i + 1, "a" if rng.random() < 0.5 else "b") for i in range(999)])
    run = cli(tmp_path, "rank", "--json", "--bootstrap", "200", *roots)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.peak_mib < PEAK_RSS_MIB, run.peak_mib  # before: a (250, 1000, 1000) array, 3.9 GB
    result = json.loads(run.stdout)
    assert result["votes"] == 999 and len(result["ranking"]) == 1000


@pytest.mark.slow
def test_report_of_two_rollouts_of_8000_latents(tmp_path):
    with SessionWriter.create(tmp_path / "s", model={"name": "s"}) as w:
        for episode in range(2):
            w.add_rollout(f"r{episode}", kind="single_chunk", actions=np.zeros((1, 9, 6)), episode_index=episode,
                          latents=np.random.default_rng(episode).normal(4.0 * episode, 1.0, (8000, 1)))
    run = cli(tmp_path, "report", "--json", "--no-cache", "--jobs", "1", tmp_path / "s")
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.peak_mib < PEAK_RSS_MIB, run.peak_mib  # before: the (16000, 16000) distances, 2.1 GB
    latents = json.loads(run.stdout)["latents"]
    assert (latents["n_vectors"], latents["silhouette_vectors"]) == (16_000, 10_000)
    assert 0.5 < latents["silhouette"] < 0.9
