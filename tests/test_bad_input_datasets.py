"""Hostile LeRobot datasets given directly to ``info``, ``report``, ``export`` and ``serve``.

The contract (docs/reliability.md, "exit code 2 and one line"): bad input is exit 2 and exactly one stderr line
``error: <file>: <what>`` naming the file and the field; one broken episode never takes the others
down; a failed export leaves no file and prints nothing else (rerun's own log lines included); a
dataset kept as symlinks (the Hugging Face hub cache) reads like any other.

Every case runs ``python -m inspector`` in a subprocess, as a user would, on a copy of one small
dataset written in the real LeRobot v3.0 layout by :mod:`inspector.data.lerobot_writer`.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from cli_processes import module_command_server

from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset

pytestmark = pytest.mark.slow  # the CLI and serve as processes

EPISODES_PARQUET = "meta/episodes/chunk-000/file-000.parquet"
DATA_PARQUET = "data/chunk-000/file-000.parquet"
FRONT_MP4 = "videos/observation.images.front/chunk-000/file-000.mp4"
LENGTHS = (12, 16, 14)


def _episode(T: int, seed: int) -> EpisodeData:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)[:, None]
    state = 30 * np.sin(2 * np.pi * t + rng.uniform(0, 1, 6)) + [0, -60, 60, 70, 0, 50]
    frames = np.zeros((T, 24, 32, 3), np.uint8)
    frames[..., 0] = np.linspace(0, 250, T, dtype=np.uint8)[:, None, None]
    return EpisodeData(f"task {seed}", state, np.roll(state, -2, axis=0), {"front": frames})


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_lerobot_dataset(tmp_path_factory.mktemp("pristine") / "so101_small",
                                 [_episode(n, i) for i, n in enumerate(LENGTHS)], units=None)


@pytest.fixture
def dataset(pristine: Path, tmp_path: Path) -> Path:
    """A fresh copy of the small dataset, to break."""
    return Path(shutil.copytree(pristine, tmp_path / "so101_small"))


def _env() -> dict[str, str]:
    # RUST_LOG as a user has it (unset): the command itself must keep rerun quiet
    return {k: v for k, v in os.environ.items() if k != "RUST_LOG"}


# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def inspector(*args: object, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return _run_command(*args, timeout=300, env=_env(), cwd=cwd)


def assert_one_line_error(run: subprocess.CompletedProcess, file: str, *words: str) -> str:
    """Exit 2 and exactly one stderr line ``error: <...file>: <what>`` with ``words`` in what."""
    assert "Traceback" not in run.stderr, run.stderr
    assert run.returncode == 2, (run.returncode, run.stderr)
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and run.stderr.endswith("\n"), run.stderr
    prefix, where, what = (lines[0].split(": ", 2) + ["", ""])[:3]
    assert prefix == "error" and where.endswith(file), lines[0]
    for word in words:
        assert word in what, lines[0]
    return what


def serve_until_serving(*paths: Path) -> tuple[str, str]:
    """Start ``inspector serve PATHS --port 0``, wait for its "serving" line (a watchdog kills
    it after 240 s), stop it; returns (that line, its stderr)."""
    proc = subprocess.Popen([sys.executable, "-m", "inspector", "serve", *map(str, paths), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    watchdog = threading.Timer(240, proc.kill)
    watchdog.start()
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        while line and not line.startswith("inspector: serving"):  # viser's banner comes first
            line = proc.stdout.readline()
    finally:
        watchdog.cancel()
        proc.terminate()
        _, err = proc.communicate(timeout=60)
    return line, err


def set_column(path: Path, column: str, edit: Callable[[list], list], typ: pa.DataType | None = None) -> None:
    table = pq.read_table(path)
    values = edit(table.column(column).to_pylist())
    array = pa.array(values, type=typ if typ is not None else table.column(column).type)
    pq.write_table(table.set_column(table.column_names.index(column), column, array), path)


def edit_info(root: Path, **fields: object) -> None:
    path = root / "meta" / "info.json"
    info = json.loads(path.read_text())
    info.update(fields)
    path.write_text(json.dumps(info))  # NaN as NaN, as a careless writer leaves it


# ----------------------------------------------------------------------------------------------
# 1. The episode index: columns of the wrong type


@pytest.mark.parametrize("column", ["episode_index", "length", "dataset_from_index",
                                    "videos/observation.images.front/from_timestamp"])
def test_a_wrong_typed_index_column_is_one_line_naming_file_and_column(dataset: Path, column: str) -> None:
    set_column(dataset / EPISODES_PARQUET, column, lambda v: [str(x) for x in v], pa.string())
    what = assert_one_line_error(inspector("info", dataset), EPISODES_PARQUET, f"'{column}'", "string")
    assert what.startswith(f"column '{column}': expected ")


def test_index_as_strings_refused_by_report_and_export_alike(dataset: Path, tmp_path: Path) -> None:
    set_column(dataset / EPISODES_PARQUET, "episode_index", lambda v: [str(x) for x in v], pa.string())
    assert_one_line_error(inspector("report", dataset, "--json", "--jobs", "1"), EPISODES_PARQUET, "'episode_index'")
    out = tmp_path / "out"
    out.mkdir()
    assert_one_line_error(inspector("export", dataset, "--episode", "0", "-o", out / "e.rrd"),
                          EPISODES_PARQUET, "'episode_index'")
    assert list(out.iterdir()) == []


def test_an_episode_listed_twice_is_refused(dataset: Path) -> None:
    set_column(dataset / EPISODES_PARQUET, "episode_index", lambda v: [v[0], v[1], v[1]])
    assert_one_line_error(inspector("info", dataset), "meta/episodes", "'episode_index' 1 is listed twice")


def test_v21_index_as_strings_is_refused(lerobot_dir: Path, tmp_path: Path) -> None:
    root = Path(shutil.copytree(lerobot_dir / "so101_v21", tmp_path / "v21"))
    lines = (root / "meta" / "episodes.jsonl").read_text().splitlines()
    row = json.loads(lines[0])
    lines[0] = json.dumps({**row, "length": str(row["length"])})
    (root / "meta" / "episodes.jsonl").write_text("\n".join(lines) + "\n")
    assert_one_line_error(inspector("info", root), "meta/episodes.jsonl", "line 1", "'length'")


def test_serve_starts_on_the_other_paths(dataset: Path, pristine: Path) -> None:
    """A dataset whose index is broken is one stderr line; the app serves the other path."""
    set_column(dataset / EPISODES_PARQUET, "length", lambda v: [str(x) for x in v], pa.string())
    serving, err = serve_until_serving(dataset, pristine)
    assert f"serving {len(LENGTHS)} episode(s) of 1 dataset(s)" in serving, (serving, err)
    assert "(1 could not be read; see the app)" in serving
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and EPISODES_PARQUET in lines[0] and "column 'length'" in lines[0], err
    assert "Traceback" not in err


def test_the_app_shows_a_broken_dataset_as_an_error_entry(dataset: Path, pristine: Path) -> None:
    from inspector.app._catalog import Catalog
    from inspector.data.sources import open_sources
    from inspector.errors import InspectorError

    set_column(dataset / EPISODES_PARQUET, "episode_index", lambda v: [float(x) for x in v], pa.float64())
    sources = open_sources([dataset, pristine], confine=True, datasets=True, keep_going=True)
    try:
        catalog = Catalog(sources, ThreadPoolExecutor(1), {})
        broken = [e for e in catalog.entries.values() if e.error is not None]
        assert len(broken) == 1 and "column 'episode_index'" in str(broken[0].error)
        assert len(catalog.entries) == len(LENGTHS) + 1
        assert catalog.entries[catalog.default_key() or ""].error is None
        with pytest.raises(InspectorError, match="episode_index"):
            catalog.load(broken[0].key)
    finally:
        sources.close()
    with pytest.raises(InspectorError, match="episode_index"):  # nothing else to serve: refused
        open_sources([dataset], confine=True, datasets=True, keep_going=True)


# ----------------------------------------------------------------------------------------------
# 2. fps in meta/info.json


@pytest.mark.parametrize("fps", [1e308, 1e-300, 0, -30, float("nan"), "30", True, 10 ** 30],
                         ids=["1e308", "1e-300", "zero", "negative", "nan", "string", "bool", "huge-int"])
def test_fps_is_validated_at_open(dataset: Path, fps: object) -> None:
    edit_info(dataset, fps=fps)
    assert_one_line_error(inspector("info", dataset), "meta/info.json", "'fps'")


@pytest.mark.parametrize("fps", [1e308, 1e-300])
def test_export_with_absurd_fps_is_one_line(dataset: Path, tmp_path: Path, fps: float) -> None:
    edit_info(dataset, fps=fps)
    out = tmp_path / "out"
    out.mkdir()
    assert_one_line_error(inspector("export", dataset, "--episode", "0", "-o", out / "e.rrd"), "meta/info.json",
                          "'fps'", "frames per second")
    assert list(out.iterdir()) == []


# ----------------------------------------------------------------------------------------------
# 3. One broken episode of several


def test_one_broken_episode_is_listed_and_the_others_report_and_export(dataset: Path, tmp_path: Path) -> None:
    def inf_in_episode_0(rows: list) -> list:
        rows[3][1] = float("inf")  # rows 0..11 are episode 0
        return rows

    set_column(dataset / DATA_PARQUET, "observation.state", inf_in_episode_0)
    run = inspector("report", dataset, "--json", "--jobs", "1", "--no-cache")
    assert run.returncode == 0 and run.stderr == "", run.stderr
    report = json.loads(run.stdout)
    assert [e["episode_index"] for e in report["episodes"]] == [1, 2]
    assert [e["length"] for e in report["episodes"]] == list(LENGTHS[1:])
    (key, error), = report["errors"].items()
    assert key.endswith("episode_000000")
    file, what = error.split(": ", 1)
    assert file.endswith(DATA_PARQUET) and "observation.state" in what and "episode 0" in what and "inf" in what

    text = inspector("report", dataset, "--jobs", "1", "--no-cache")
    assert text.returncode == 0
    assert [line for line in text.stdout.splitlines() if line.startswith("error: ")] == [f"error: {error}"]

    dest = tmp_path / "e1.rrd"
    ok = inspector("export", dataset, "--episode", "1", "-o", dest, "--no-cache")
    assert ok.returncode == 0, ok.stderr
    assert dest.stat().st_size > 0
    assert_one_line_error(inspector("export", dataset, "--episode", "0", "-o", tmp_path / "e0.rrd"),
                          DATA_PARQUET, "episode 0")
    assert not (tmp_path / "e0.rrd").exists()


# ----------------------------------------------------------------------------------------------
# 4. report DATASET --html


def test_report_html_of_a_dataset_is_a_page_of_its_episodes(dataset: Path, tmp_path: Path) -> None:
    set_column(dataset / DATA_PARQUET, "action",
               lambda rows: [[float("nan")] * 6 if i == 20 else r for i, r in enumerate(rows)])  # episode 1
    page = tmp_path / "page.html"
    run = inspector("report", dataset, "--html", page, "--jobs", "1", "--no-cache")
    assert run.returncode == 0, run.stderr
    assert run.stderr == f"wrote {page}\n"
    html = page.read_text()
    assert html.rstrip().endswith("</html>")
    table = re.search(r'<table id="episodes".*?</table>', html, re.S)
    assert table is not None
    rows = re.findall(r"<tr data-key=\"(e\d+)\">(.*?)</tr>", table.group(0))
    assert [re.findall(r"<td[^>]*>(.*?)</td>", cells)[1] for _, cells in rows] == ["0", "2"]
    assert "task 2" in table.group(0)
    for key in ("tracking-by-episode", "tracking-per-joint"):
        figure = re.search(rf'<figure id="{key}".*?</figure>', html, re.S)
        assert figure is not None and "<svg" in figure.group(0), key
    assert "1 episode(s) not reported" in html and "episode 1" in html and DATA_PARQUET in html
    assert "<table id=\"rollouts\"" not in html  # no rollouts: no empty rollout section


def test_report_html_refusal_leaves_no_page(dataset: Path, tmp_path: Path) -> None:
    set_column(dataset / EPISODES_PARQUET, "length", lambda v: [str(x) for x in v], pa.string())
    page = tmp_path / "page.html"
    assert_one_line_error(inspector("report", dataset, "--html", page), EPISODES_PARQUET, "'length'")
    assert list(tmp_path.iterdir()) == [dataset]


# ----------------------------------------------------------------------------------------------
# 5. A failed export is one line: rerun's own log lines stay out of it


def _drop_video(root: Path) -> None:
    (root / FRONT_MP4).unlink()


def _shorten_video(root: Path) -> None:
    from inspector.data.video import decode, encode_h264

    frames, _ = decode(root / FRONT_MP4)
    encode_h264(root / FRONT_MP4, frames[: LENGTHS[0] + 4], 30)  # episode 1 ends inside it, 2 after


def _nan_window(root: Path) -> None:
    set_column(root / EPISODES_PARQUET, "videos/observation.images.front/from_timestamp",
               lambda v: [float("nan") if i == 1 else x for i, x in enumerate(v)])


@pytest.mark.parametrize("breaks, episode", [(_drop_video, 0), (_shorten_video, 1), (_shorten_video, 2),
                                             (_nan_window, 1)],
                         ids=["missing", "shorter-inside", "shorter-beyond", "nan-window"])
def test_a_failed_camera_export_prints_exactly_one_line(dataset: Path, tmp_path: Path,
                                                        breaks: Callable[[Path], None], episode: int) -> None:
    breaks(dataset)
    out = tmp_path / "out"
    out.mkdir()
    run = inspector("export", dataset, "--episode", episode, "-o", out / "e.rrd", "--no-cache")
    what = assert_one_line_error(run, FRONT_MP4)
    if breaks is _nan_window:  # the field named, in our words
        assert "'videos/observation.images.front/from_timestamp' = nan" in what, what
    assert "\x1b" not in run.stderr and "re_sdk" not in run.stderr
    assert list(out.iterdir()) == []


# ----------------------------------------------------------------------------------------------
# 6. Files that are symlinks: the Hugging Face hub cache


def hub_snapshot(src: Path, hub: Path, repo_id: str = "me/so101_small") -> Path:
    """``src`` laid out as ``huggingface_hub.snapshot_download`` leaves it: every file of
    ``snapshots/<revision>/`` a relative symlink into ``blobs/<sha256>``."""
    repo = hub / ("datasets--" + repo_id.replace("/", "--"))
    snapshot = repo / "snapshots" / "0123abcd"
    (repo / "blobs").mkdir(parents=True)
    for f in sorted(src.rglob("*")):
        if f.is_file():
            blob = repo / "blobs" / hashlib.sha256(f.read_bytes()).hexdigest()
            shutil.copyfile(f, blob)
            link = snapshot / f.relative_to(src)
            link.parent.mkdir(parents=True, exist_ok=True)
            link.symlink_to(os.path.relpath(blob, link.parent))
    return snapshot


def test_a_hub_cache_snapshot_reads_like_any_dataset(pristine: Path, tmp_path: Path) -> None:
    snapshot = hub_snapshot(pristine, tmp_path / "hub")
    assert (snapshot / "meta" / "info.json").is_symlink() and (snapshot / FRONT_MP4).is_symlink()
    info = inspector("info", snapshot, "--json")
    assert info.returncode == 0, info.stderr
    assert [e["length"] for e in json.loads(info.stdout)["episodes"]] == list(LENGTHS)
    report = inspector("report", snapshot, "--json", "--jobs", "1", "--no-cache")
    assert report.returncode == 0, report.stderr
    rows = json.loads(report.stdout)["episodes"]
    assert [r["episode_index"] for r in rows] == [0, 1, 2] and {r["dataset"] for r in rows} == {"me/so101_small"}
    dest = tmp_path / "e2.rrd"
    export = inspector("export", snapshot, "--episode", "2", "-o", dest, "--no-cache")
    assert export.returncode == 0, export.stderr


def test_the_app_serves_a_hub_cache_snapshot_and_nothing_beyond_its_repo(pristine: Path, tmp_path: Path) -> None:
    from inspector.app._catalog import Catalog
    from inspector.app._frames import READY
    from inspector.app._robot import joint_child_links
    from inspector.data.sources import open_sources
    from inspector.errors import InspectorError

    snapshot = hub_snapshot(pristine, tmp_path / "hub")
    sources = open_sources([snapshot], confine=True, datasets=True)
    try:
        with ThreadPoolExecutor(1) as pool:
            catalog = Catalog(sources, pool, joint_child_links())
            keys = catalog.keys()
            assert len(keys) == len(LENGTHS) and all(k.startswith("me/so101_small / episode ") for k in keys)
            loaded = catalog.load(keys[1])  # joints and frames read through the links
            assert loaded.timeline.n_steps == LENGTHS[1] and loaded.timeline.gt.views == ["front"]
            assert loaded.frames.done.wait(120)
            assert loaded.frames.status["front"] == READY
            assert loaded.frames.pair("front", LENGTHS[1] - 1).gt
    finally:
        sources.close()

    # a link out of the hub repository (another repo's blobs, or anywhere) is still refused
    elsewhere = tmp_path / "elsewhere.json"
    info = snapshot / "meta" / "info.json"
    shutil.copyfile(info, elsewhere)
    info.unlink()
    info.symlink_to(elsewhere)
    with pytest.raises(InspectorError, match="resolves outside the served roots"):
        open_sources([snapshot], confine=True, datasets=True)


def test_serve_starts_on_a_hub_cache_snapshot(pristine: Path, tmp_path: Path) -> None:
    snapshot = hub_snapshot(pristine, tmp_path / "hub")
    serving, err = serve_until_serving(snapshot)
    assert f"serving {len(LENGTHS)} episode(s) of 1 dataset(s)" in serving, (serving, err)
    assert "error" not in err, err
