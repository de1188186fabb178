"""Another tool's output given to ``import``, ``report`` and ``serve``: what is read is never lost,
a GT episode the dataset lacks is a warning, and a second report of an unchanged output reads the
metrics cache.

- ``import FORMAT SRC -o DEST --overwrite`` where DEST is SRC, holds it or lies inside it (or holds
  the GT dataset), read through symbolic links, is one line naming both, and both are left as
  they were.
- An offline-inference run (or a DreamZero-SO101 rollout) whose GT episode the dataset lacks is
  reported without GT metrics (null), with a top-level warning naming it and the episode; the
  app's card says so.
- The metrics cache keys a raw layout's rollouts by its source files: three reports of an
  unchanged output leave one entry per rollout and print the same bytes as ``--no-cache``; an
  edited CSV or a touched video is a miss.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_processes import module_command_server
from eval_outputs import write_eval
from groot_dreams_layout import write_groot_dreams
from offline_runs import write_run

from inspector.data.importers.dreamzero_offline import import_offline
from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset
from inspector.data.video import encode_h264

pytestmark = pytest.mark.slow  # imports and reports through the CLI

REPO = Path(__file__).resolve().parents[1]


# the commands run as processes forked from one that imported the CLI once (some twenty reports and
# imports: the start-up would be a large part of each)
_command_server, _run_command = module_command_server()


def cli(*argv, cache: Path | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, **({"INSPECTOR_CACHE_DIR": str(cache)} if cache is not None else {})}
    return _run_command(*argv, timeout=300, env=env, cwd=REPO)


def tree(root: Path) -> dict[str, str]:
    """Every file under ``root`` (links not followed) by its path, with its content's hash."""
    out = {}
    for dirpath, _, names in os.walk(root):
        for name in names:
            p = Path(dirpath) / name
            out[str(p.relative_to(root))] = "link" if p.is_symlink() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def write_dreamzero(path: Path, episode: int | None = 0) -> None:
    """A DreamZero-SO101 autoregressive rollout: 3 chunks of 24 actions, 9 executed each."""
    path.mkdir(parents=True)
    np.save(path / "action_trace.npy", 10 * np.sin(np.arange(3 * 24 * 6).reshape(3, 24, 6) / 20))
    meta = {"prompt": "Pick the red cube", "frames_per_step": 9, **({"episode": episode} if episode is not None else {})}
    (path / "meta.json").write_text(json.dumps(meta))
    encode_h264(path / "rollout_front.mp4", [np.full((64, 96, 3), 9 * i, np.uint8) for i in range(27)], fps=30)


def earlier_session(runs: Path, dest: Path) -> None:
    """A session at ``dest`` imported from the offline runs under ``runs`` (in this process: the
    import command is what the tests run after it)."""
    _, errors = import_offline(runs, dest, log=lambda _: None)
    assert errors == {}


def write_dataset(root: Path) -> Path:
    """A LeRobot dataset of episodes 0 and 1."""
    rng = np.random.default_rng(3)
    write_lerobot_dataset(root, [EpisodeData("Pick the red cube", rng.normal(0, 20, (n, 6)), rng.normal(0, 20, (n, 6)))
                                 for n in (40, 120)])
    return root


# A small source of each import format, written at the path given.
SOURCES = {
    "dreamzero-offline": lambda p: write_run(p, 1, mp4=False),
    "dreamzero-so101": lambda p: write_dreamzero(p),
    "lerobot-eval": lambda p: write_eval(p, {("pick", 0): [True]}, steps=12),
    "groot-dreams": lambda p: write_groot_dreams(p, [("pick the cube", 12)]),
}


# How DEST stands to SRC: (SRC, DEST, where the source's files go) under a directory d, where d/s
# is a session already (but for src-holds-dest).
def _dest_holds_src(d: Path) -> tuple[Path, Path, Path]:
    return d / "s" / "raw", d / "s", d / "s" / "raw"


def _dest_holds_src_through_a_link(d: Path) -> tuple[Path, Path, Path]:
    (d / "link").symlink_to(d / "s")
    return d / "link" / "raw", d / "s", d / "s" / "raw"


def _same(d: Path) -> tuple[Path, Path, Path]:
    return d / "s", d / "s", d / "s"


def _same_through_a_link(d: Path) -> tuple[Path, Path, Path]:
    (d / "link").symlink_to(d / "s")
    return d / "link", d / "s", d / "s"


def _src_holds_dest(d: Path) -> tuple[Path, Path, Path]:
    return d / "s", d / "s" / "session", d / "s"


OVERLAPS = {"dest-holds-src": _dest_holds_src, "dest-holds-src-through-a-link": _dest_holds_src_through_a_link,
            "same": _same, "same-through-a-link": _same_through_a_link, "src-holds-dest": _src_holds_dest}


# every format in the plain relations, through a link once (offline runs)
CASES = [(f, o) for o in sorted(OVERLAPS) for f in sorted(SOURCES) if "link" not in o or f == "dreamzero-offline"]


@pytest.mark.parametrize(("fmt", "overlap"), CASES)
def test_an_import_never_replaces_or_writes_into_its_source(fmt, overlap, tmp_path):
    d = tmp_path
    if overlap != "src-holds-dest":  # an earlier session at d/s, which --overwrite may replace
        write_run(d / "other" / "run", 1, mp4=False)
        earlier_session(d / "other" / "run", d / "s")
    src, dest, files = OVERLAPS[overlap](d)
    SOURCES[fmt](d / "written")
    files.mkdir(parents=True, exist_ok=True)
    for p in (d / "written").iterdir():
        p.rename(files / p.name)
    before = tree(d)
    out = cli("import", fmt, src, "-o", dest, "--overwrite")
    assert out.returncode == 2, out.stdout + out.stderr
    assert out.stderr.count("\n") == 1 and out.stderr.startswith(f"error: {dest}: "), out.stderr
    assert f"the source {src}" in out.stderr and "write the session elsewhere" in out.stderr, out.stderr
    assert tree(d) == before  # nothing deleted, nothing written (no staging directory either)


def test_an_import_never_replaces_its_gt_dataset(tmp_path):
    """The GT dataset kept inside the session (as the demo keeps its own): --overwrite refuses."""
    write_run(tmp_path / "runs" / "r", 1, mp4=False, sidecar={"episode": 1})
    earlier_session(tmp_path / "runs", tmp_path / "s")
    write_dataset(tmp_path / "s" / "dataset")
    before = tree(tmp_path / "s")
    for fmt in ("dreamzero-offline", "dreamzero-so101"):
        src = tmp_path / "runs" if fmt == "dreamzero-offline" else tmp_path / "dz"
        if fmt == "dreamzero-so101":
            write_dreamzero(src / "ep001", episode=1)
        out = cli("import", fmt, src, "-o", tmp_path / "s", "--overwrite", "--dataset", tmp_path / "s" / "dataset")
        assert out.returncode == 2 and out.stderr.count("\n") == 1, out.stderr
        assert f"holds the GT dataset {(tmp_path / 's' / 'dataset').resolve()}" in out.stderr, out.stderr
        assert tree(tmp_path / "s") == before


def test_an_import_beside_its_source_still_works(tmp_path):
    """Names that only share a prefix (runs, runs2) are apart."""
    write_run(tmp_path / "runs" / "r", 1, mp4=False)
    out = cli("import", "dreamzero-offline", tmp_path / "runs", "-o", tmp_path / "runs2")
    assert out.returncode == 0, out.stderr


# ----------------------------------------------------------------------------------------------
# A GT episode the dataset lacks


def test_an_offline_run_whose_episode_is_missing_is_shown_without_gt(tmp_path):
    ds = write_dataset(tmp_path / "ds")
    write_run(tmp_path / "runs" / "lost", 2, sidecar={"dataset": "../../ds", "episode": 7})
    out = cli("report", "-j", "1", "--json", "--no-cache", tmp_path / "runs" / "lost")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    (row,) = report["rollouts"]
    assert row["tag"] == "lost" and row["episode_index"] == 7
    for metric in ("rmse_deg", "time_aligned_drift", "best_match_drift", "ee_error_mm", "tempo"):
        assert row[metric] is None, metric
    assert report["warnings"] == ["lost: dataset ds has no episode 7 (episodes 0..1)"]
    assert "errors" not in report
    text = cli("report", "-j", "1", "--no-cache", tmp_path / "runs")
    assert text.returncode == 0 and "warning: lost: dataset ds has no episode 7" in text.stdout, text.stderr

    # with a run that has its episode, through --dataset: that one is measured, this one warned
    write_run(tmp_path / "runs" / "found", 1, seed=1, sidecar={"episode": 1})
    (tmp_path / "runs" / "lost" / "inspector_gt.json").write_text('{"episode": 7}')
    out = cli("report", "-j", "1", "--json", "--no-cache", tmp_path / "runs", "--dataset", ds)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    rows = {r["tag"]: r for r in report["rollouts"]}
    assert rows["found"]["rmse_deg"] is not None and rows["lost"]["rmse_deg"] is None
    assert report["warnings"] == ["lost: dataset ds has no episode 7 (episodes 0..1)"]

    # import writes it too (the log says why it has no GT joints); --episode the dataset lacks is refused
    imported = cli("import", "dreamzero-offline", tmp_path / "runs", "-o", tmp_path / "s", "--dataset", ds)
    assert imported.returncode == 0, imported.stderr
    assert "lost: autoregressive" in imported.stdout and "has no episode 7" in imported.stdout
    refused = cli("import", "dreamzero-offline", tmp_path / "runs", "-o", tmp_path / "s2", "--dataset", ds,
                  "--episode", "9")
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
    assert "episode 9 is out of range" in refused.stderr and "--episode" in refused.stderr
    assert not (tmp_path / "s2").exists()

    from inspector.app import HeadlessClient, InspectorApp
    from inspector.cache import MetricsCache
    from inspector.data.sources import open_sources

    app = InspectorApp(open_sources([tmp_path / "runs"], dataset=str(ds), confine=True), port=0,
                       metrics_cache=MetricsCache(enabled=False))
    try:
        with HeadlessClient(app.port):
            tab = app.wait_for_tabs(1)[0]
            assert tab.open(next(k for k in app.catalog.keys() if k.endswith("lost")))
            assert "dataset ds has no episode 7" in tab.controls.card.content
            assert not tab.loaded.timeline.has_gt_joints
    finally:
        app.stop()


def test_a_dreamzero_rollout_whose_episode_is_missing_is_shown_without_gt(tmp_path):
    ds = write_dataset(tmp_path / "ds")
    write_dreamzero(tmp_path / "dz" / "ep005", episode=5)
    write_dreamzero(tmp_path / "dz" / "ep001", episode=1)
    out = cli("report", "-j", "1", "--json", "--no-cache", tmp_path / "dz", "--dataset", ds)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    rows = {r["tag"]: r for r in report["rollouts"]}
    assert rows["ep005"]["time_aligned_drift"] is None and rows["ep001"]["time_aligned_drift"] is not None
    assert report["warnings"] == ["ep005: dataset ds has no episode 5 (episodes 0..1)"]


# ----------------------------------------------------------------------------------------------
# The metrics cache on raw layouts


def entries(cache: Path) -> int:
    return sum(1 for _ in (cache / "metrics").rglob("*.json")) if (cache / "metrics").is_dir() else 0


def _write_offline(root: Path) -> tuple[list[str], Path, Path]:
    """(extra report arguments, a file to edit, a video to touch)"""
    write_dataset(root / "ds")
    write_run(root / "src" / "a", 2, sidecar={"dataset": "../../ds", "episode": 1})
    write_run(root / "src" / "b", 1, seed=1, mp4=False, sidecar={"dataset": "../../ds", "episode": 0})
    return [], root / "src" / "a" / "predicted_actions.csv", root / "src" / "a" / "predicted_video.mp4"


def _write_dreamzero(root: Path) -> tuple[list[str], Path, Path]:
    write_dataset(root / "ds")
    write_dreamzero(root / "src" / "ep000", episode=0)
    write_dreamzero(root / "src" / "ep001", episode=1)
    return ["--dataset", str(root / "ds")], root / "src" / "ep000" / "meta.json", root / "src" / "ep001" / "rollout_front.mp4"


def _write_eval(root: Path) -> tuple[list[str], Path, Path]:
    write_eval(root / "src", {("pick", 0): [True, False]}, steps=12)
    return [], root / "src" / "eval_info.json", next((root / "src" / "videos").rglob("pred_episode_0.mp4"))


RAW = {"dreamzero-offline": _write_offline, "dreamzero-so101": _write_dreamzero, "lerobot-eval": _write_eval}


def _edit(path: Path) -> None:
    if path.suffix == ".csv":  # one joint of the first row, moved by a degree
        lines = path.read_text().splitlines()
        fields = lines[1].split(",")
        fields[1] = f"{float(fields[1]) + 1.0:.8f}"
        lines[1] = ",".join(fields)
        path.write_text("\n".join(lines) + "\n")
    else:  # JSON: the same content, rewritten (another size)
        path.write_text(json.dumps(json.loads(path.read_text()), indent=1))


@pytest.mark.parametrize("fmt", sorted(RAW))
def test_reports_of_an_unchanged_raw_output_read_the_cache(fmt, tmp_path):
    extra, edited, video = RAW[fmt](tmp_path)
    cache = tmp_path / "cache"
    first = cli("report", "-j", "1", "--json", tmp_path / "src", *extra, cache=cache)
    assert first.returncode == 0, first.stderr
    n = len(json.loads(first.stdout)["rollouts"])
    assert n >= 2 and entries(cache) == n
    for _ in range(2):
        again = cli("report", "-j", "1", "--json", tmp_path / "src", *extra, cache=cache)
        assert again.returncode == 0 and again.stdout == first.stdout, again.stderr
        assert entries(cache) == n
    uncached = cli("report", "-j", "1", "--json", "--no-cache", tmp_path / "src", *extra)
    assert uncached.stdout == first.stdout

    _edit(edited)
    assert cli("report", "-j", "1", "--json", tmp_path / "src", *extra, cache=cache).returncode == 0
    grown = entries(cache)
    assert grown > n  # the edited rollout (every rollout, where it is a file they share)
    os.utime(video, ns=(video.stat().st_atime_ns, video.stat().st_mtime_ns + 10**9))  # touched
    assert cli("report", "-j", "1", "--json", tmp_path / "src", *extra, cache=cache).returncode == 0
    assert entries(cache) > grown
    if fmt != "lerobot-eval":  # a rollout of its own directory: the others still hit
        assert entries(cache) == grown + 1 and grown == n + 1


def test_reports_of_a_groot_dreams_dump_write_no_entries(tmp_path):
    """Its episodes are read as a dataset's (no video metrics to keep): the cache stays empty."""
    write_groot_dreams(tmp_path / "dump", [("pick the cube", 12), ("place it", 10)])
    cache = tmp_path / "cache"
    outputs = [cli("report", "-j", "1", "--json", tmp_path / "dump", cache=cache) for _ in range(3)]
    assert all(o.returncode == 0 for o in outputs), outputs[0].stderr
    assert outputs[0].stdout == outputs[1].stdout == outputs[2].stdout
    assert entries(cache) == 0
