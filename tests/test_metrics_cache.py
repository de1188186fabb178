"""The metrics cache is only ever a shortcut: an entry is read back only as it was written, any
other is computed again and written anew, and the report is then byte for byte the ``--no-cache``
one. A cache that cannot be written (a file where its directory should be, a read-only or full
file system) is one warning per command, and the command's own output is still written; an output
that cannot be written is one error naming it.

Read-only and full file systems are real: a tmpfs mounted in a private mount namespace
(``unshare``), filled up or mounted read-only; the tests that need one skip where no namespace can
be made.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from demo_copies import demo_copy
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from inspector.cache import SCHEMA, decode_entry
from inspector.data.video import VideoClip, encode_h264
from inspector.report.build import FIELDS_SET_AFTER_CACHE
from inspector.rows.entries import MetricsEntry, is_consistent
from inspector.rows.rollout import RolloutRow
from inspector.schema import mismatch

pytestmark = pytest.mark.slow  # the CLI as processes

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "sessions" / "demo"
# Three rollouts (autoregressive, single-chunk, slowed), each with two views: across two workers.
ROLLOUTS = ("bias_elbow", "single_f000", "tempo_0.8x")
# The autoregressive ones cut to their first chunks (of 49): every command here decodes and
# compares half the video, and the slowed one still reads as slowed (its tempo about 0.8).
CHUNKS = 24
# Where only what happens to the cache and the outputs matters: two one-chunk rollouts (from two
# start frames, so two tasks: a pool of two workers, each failing to write its entry).
SMALL = ("single_f000", "single_f076")


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = demo_copy(tmp_path_factory.mktemp("cache"), ROLLOUTS)
    for tag in ("bias_elbow", "tempo_0.8x"):
        _keep_chunks(root / "rollouts" / tag, CHUNKS)
    return root


def _keep_chunks(rollout: Path, chunks: int) -> None:
    """Cut a rollout to its first ``chunks`` chunks: their actions, states and frames."""
    meta = json.loads((rollout / "rollout.json").read_text())
    np.save(rollout / "actions.npy", np.load(rollout / "actions.npy")[:chunks])
    np.save(rollout / "states.npy", np.load(rollout / "states.npy")[:chunks + 1])
    for view in meta["views"]:
        video = rollout / "video" / f"{view}.mp4"
        frames = [rgb for _, rgb in itertools.islice(VideoClip(video).iter_frames(), chunks * meta["frames_per_chunk"])]
        encode_h264(video, frames, meta["fps"])


def inspector(*args: Any, cache: Path | str | None = None, stdout: Path | None = None,
              wrap: list[str] | None = None, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """``python -m inspector ARGS`` with its own cache directory (and stdout into a file)."""
    command = [*(wrap or []), sys.executable, "-m", "inspector", *map(str, args)]
    environment = {**os.environ, **(env or {})}
    if cache is not None:
        environment["INSPECTOR_CACHE_DIR"] = str(cache)
    if stdout is None:
        return subprocess.run(command, capture_output=True, text=True, env=environment, timeout=600, cwd=REPO)
    with open(stdout, "w") as fh:
        return subprocess.run(command, stdout=fh, stderr=subprocess.PIPE, text=True, env=environment,
                              timeout=600, cwd=REPO)


@pytest.fixture(scope="module")
def no_cache_report(session: Path) -> str:
    # in this process; the warm cache's report, in workers, must match it byte for byte
    out = inspector("report", session, "--json", "--no-cache", "--jobs", "1")
    assert out.returncode == 0 and out.stderr == "", out.stderr
    return out.stdout


@pytest.fixture(scope="module")
def small_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return demo_copy(tmp_path_factory.mktemp("small"), SMALL)


@pytest.fixture(scope="module")
def small_no_cache_report(small_session: Path) -> str:
    out = inspector("report", small_session, "--json", "--no-cache", "--jobs", "1")
    assert out.returncode == 0 and out.stderr == "", out.stderr
    assert [r["tag"] for r in json.loads(out.stdout)["rollouts"]] == list(SMALL)
    return out.stdout


@pytest.fixture(scope="module")
def warm_cache(session: Path, no_cache_report: str, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A cache holding every rollout's entry (row and video metrics), as one report leaves it."""
    cache = tmp_path_factory.mktemp("warm")
    out = inspector("report", session, "--json", cache=cache)
    assert out.returncode == 0 and out.stdout == no_cache_report, out.stderr
    assert len(entry_files(cache)) == len(ROLLOUTS)
    return cache


def entry_files(cache: Path) -> list[Path]:
    return sorted((cache / "metrics").glob("*/*.json"))


def read_back(path: Path) -> dict[str, Any] | None:
    return decode_entry(path.read_bytes(), path.stem, MetricsEntry)


@pytest.fixture(scope="module")
def entry_bytes(warm_cache: Path) -> list[tuple[Path, bytes]]:
    """Each entry file with its bytes: read once for the properties' hundreds of examples."""
    return [(path, path.read_bytes()) for path in entry_files(warm_cache)]


# ----------------------------------------------------------------------------------------------
# One definition: what the report writes is what the cache accepts


AFTER_CACHE = FIELDS_SET_AFTER_CACHE  # set on each row after the cache: outcomes, what the source says


def test_every_row_written_is_a_rollout_row_and_reads_back_as_written(warm_cache: Path, no_cache_report: str):
    rows = {r["tag"]: r for r in json.loads(no_cache_report)["rollouts"]}
    for path in entry_files(warm_cache):
        entry = read_back(path)
        assert entry is not None and mismatch(entry["row"], RolloutRow) is None
        # the report adds the outcomes and what the source says after the cache (they change
        # without the rollout changing)
        reported = {k: v for k, v in rows[entry["row"]["tag"]].items() if k not in AFTER_CACHE}
        assert entry["row"] == reported
        assert set(entry["video"]) == {"front", "wrist"}


def _tasks(session: Path, cache: Path, jobs: int) -> list:
    from inspector.data.sources import open_sources
    from inspector.report.build import DEFAULT_LIMIT_MARGIN_DEG
    from inspector.rows.tasks import plan_tasks

    sources = open_sources([session], lazy=True)
    try:
        return plan_tasks(sources.sessions, jobs, DEFAULT_LIMIT_MARGIN_DEG, str(cache))
    finally:
        sources.close()


def test_a_fully_cached_report_starts_no_workers(session: Path, warm_cache: Path, no_cache_report: str) -> None:
    """Every row in the cache: the report reads them itself, with no process started for it."""
    import multiprocessing

    from inspector.rows.tasks import run_tasks

    tasks = _tasks(session, warm_cache, jobs=2)
    assert len(tasks) >= 2  # what would take a pool of two
    outcomes = []
    for batch in run_tasks(tasks, 2):
        assert multiprocessing.active_children() == []
        outcomes += batch
    rows = {r["tag"]: r for r in json.loads(no_cache_report)["rollouts"]}
    assert sorted(o.tag for o in outcomes) == sorted(ROLLOUTS) and all(o.cached for o in outcomes)
    for o in outcomes:
        assert o.row == {k: v for k, v in rows[o.tag].items() if k not in AFTER_CACHE}


def test_a_report_looks_up_until_its_first_miss(session: Path, warm_cache: Path, tmp_path: Path) -> None:
    """What is left after the first rollout missing from the cache goes to the workers, untouched."""
    from inspector.rows.tasks import found_in_cache

    cache = tmp_path / "cache"
    shutil.copytree(warm_cache, cache)
    tasks = _tasks(session, cache, jobs=2)
    tags = [tag for task in tasks for tag in task.tags]
    found, left = found_in_cache(tasks, 100)
    assert [o.tag for batch in found for o in batch] == tags and left == []
    found, left = found_in_cache(tasks, len(tags) - 1)  # no more than it may look up
    assert [tag for task in left for tag in task.tags] == tags[-len(tasks[-1].tags):]
    for path in entry_files(cache):
        if read_back(path)["row"]["tag"] == tags[1]:
            path.unlink()
    found, left = found_in_cache(tasks, 100)
    assert [o.tag for batch in found for o in batch] == tags[:1] and all(o.cached for b in found for o in b)
    assert [tag for task in left for tag in task.tags] == tags[1:]


# ----------------------------------------------------------------------------------------------
# Properties: any corrupted entry is a miss, or (written with a valid header) one of the right types


@st.composite
def byte_corruptions(draw: st.DrawFn, data: bytes, other: bytes) -> bytes:
    """``data`` with bytes cut, flipped, inserted or replaced, or another entry's bytes."""
    kind = draw(st.sampled_from(["truncate", "flip", "insert", "delete", "other", "garbage", "body"]))
    event(kind)
    i = draw(st.integers(0, len(data) - 1))
    if kind == "truncate":
        return data[:i]
    if kind == "flip":
        return data[:i] + bytes([data[i] ^ draw(st.integers(1, 255))]) + data[i + 1:]
    if kind == "insert":
        return data[:i] + draw(st.binary(min_size=1, max_size=8)) + data[i:]
    if kind == "delete":
        return data[:i] + data[i + draw(st.integers(1, 64)):]
    if kind == "other":  # another rollout's entry, whole, under this key
        return other
    if kind == "body":  # the header kept, the record replaced by any JSON
        head = data.partition(b"\n")[0]
        return head + b"\n" + json.dumps(draw(JSON_VALUES)).encode()
    return draw(st.binary(max_size=64) | st.sampled_from([b"", b"\n", b"[" * 100_000, b"null\nnull"]))


JSON_SCALARS = (st.none() | st.booleans() | st.integers() | st.integers(-(10 ** 30), 10 ** 30)
                | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=6)
                | st.sampled_from(["front", "wrist", "autoregressive", "shoulder_pan", SCHEMA]))
JSON_VALUES = st.recursive(JSON_SCALARS, lambda inner: st.lists(inner, max_size=4)
                           | st.dictionaries(st.text(max_size=6), inner, max_size=3), max_leaves=10)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_a_corrupted_entry_file_is_a_miss(entry_bytes: list[tuple[Path, bytes]], data: st.DataObject) -> None:
    """Any change to an entry's bytes (or another rollout's entry under its key) makes it a miss:
    nothing but the record as written is ever read."""
    (path, original), (other, other_bytes) = entry_bytes[data.draw(st.integers(0, len(entry_bytes) - 1))], entry_bytes[0]
    corrupted = data.draw(byte_corruptions(original, other_bytes if other != path else b""))
    entry = decode_entry(corrupted, path.stem, MetricsEntry)
    if entry is not None:
        event("unchanged record")
    assert entry is None or entry == read_back(path)


@pytest.fixture(scope="module")
def entry_records(entry_bytes: list[tuple[Path, bytes]]) -> list[tuple[str, bytes, list[tuple]]]:
    """Each entry's key, record (its bytes after the header) and the paths in it, found once."""
    records = [(path.stem, data.partition(b"\n")[2]) for path, data in entry_bytes]
    return [(key, body, _leaves(json.loads(body))) for key, body in records]


def _leaves(value: Any, path: tuple = ()) -> list[tuple]:
    """Paths of every leaf and container of a JSON value."""
    found = [path]
    if isinstance(value, dict):
        found += [p for k, v in value.items() for p in _leaves(v, (*path, k))]
    elif isinstance(value, list):
        found += [p for i, v in enumerate(value) for p in _leaves(v, (*path, i))]
    return found


def _get(value: Any, path: tuple) -> Any:
    for step in path:
        value = value[step]
    return value


def _kind(value: Any) -> str:
    return "bool" if isinstance(value, bool) else type(value).__name__


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_an_entry_of_the_wrong_shape_is_a_miss(entry_records: list[tuple[str, bytes, list[tuple]]],
                                               data: st.DataObject) -> None:
    """An entry written with a valid header but a record changed anywhere (a value replaced by any
    JSON, a key dropped or added, NaN): read as a miss, or as an entry of the declared types,
    never anything that breaks its readers. A value replaced by one of another JSON type (say a
    string for a number, an integer for a float, an object for a list) is always a miss."""
    key, body, leaves = entry_records[data.draw(st.integers(0, len(entry_records) - 1))]
    record = json.loads(body)  # a fresh copy to change
    # an index, as sampled_from draws one, without labelling (hashing, scanning) every path each time
    target = leaves[data.draw(st.integers(0, len(leaves) - 1))]
    how = data.draw(st.sampled_from(["replace", "drop", "add", "nan"] if target else ["replace"]))
    event(f"{how} {'.'.join(str(s) for s in target[:2] if not isinstance(s, int))}")
    must_miss = how == "nan"
    if how == "replace":
        new = data.draw(JSON_VALUES)
        old = _get(record, target)
        must_miss = old is not None and new is not None and _kind(new) != _kind(old)
        if target:
            _get(record, target[:-1])[target[-1]] = new
        else:
            record = new
    elif how == "drop":
        parent = _get(record, target[:-1])
        must_miss = isinstance(parent, dict) and (len(target) <= 2 and target[0] == "row"
                                                  or target in (("row",), ("video",)))
        del parent[target[-1]]
    elif how == "add":
        parent = _get(record, target[:-1])
        if isinstance(parent, dict):
            parent["zz_unknown"] = 1
            must_miss = target[:1] == ("row",) and len(target) == 2  # a row has exactly its fields
        else:
            parent.append(1.0)
    else:
        if target and isinstance(_get(record, target[:-1]), (dict, list)):
            _get(record, target[:-1])[target[-1]] = float("nan")
    crafted = _crafted(key, json.dumps(record).encode())  # NaN written as JSON does not have it
    entry = decode_entry(crafted, key, MetricsEntry)
    if must_miss:
        assert entry is None, (how, target)
    if entry is None or not is_consistent(entry):  # (what read_entry refuses)
        event("miss")
        return
    event("read")
    assert mismatch(entry, MetricsEntry) is None
    _use(entry)


def _use(entry: dict[str, Any]) -> None:
    """What the report does with a cached row and what export does with cached video metrics."""
    from inspector.analysis.video_metrics import VideoMetrics
    from inspector.report.build import format_report
    from inspector.rows.rollout import aggregate

    for record in entry["video"].values():
        VideoMetrics.from_json(record).mean_psnr_db  # noqa: B018 - computing it is the check
    if entry["row"] is not None:
        rows = [entry["row"]]
        json.dumps(rows, allow_nan=False)
        format_report({"rollouts": rows, "aggregate": aggregate(rows)})


# ----------------------------------------------------------------------------------------------
# Through the command line: a bad entry is recomputed, rewritten, and the report is --no-cache's


def _crafted(key: str, body: bytes) -> bytes:
    """An entry file of ``body`` with a valid header: only the record's own check can refuse it."""
    header = {"schema": SCHEMA, "key": key, "sha256": hashlib.sha256(body).hexdigest()}
    return json.dumps(header).encode() + b"\n" + body


def _rewrite(path: Path, change) -> None:
    """Write ``change(record)`` under the entry's key with a valid header (a crafted entry)."""
    record = json.loads(path.read_bytes().partition(b"\n")[2])
    path.write_bytes(_crafted(path.stem, json.dumps(change(record)).encode()))


def _with(record: dict, **row_fields: Any) -> dict:
    return {**record, "row": {**record["row"], **row_fields}}


def _video(record: dict, psnr: Any) -> dict:
    return {"row": None, "video": {v: {**m, "psnr_db": psnr} for v, m in record["video"].items()}}


CORRUPTIONS = {
    "row is an integer": lambda p: _rewrite(p, lambda r: {**r, "row": 5}),
    "rmse a string": lambda p: _rewrite(p, lambda r: _with(r, rmse_deg="3.1")),
    "a count a float": lambda p: _rewrite(p, lambda r: _with(r, limit_violations={
        **r["row"]["limit_violations"], "count": float(r["row"]["limit_violations"]["count"])})),
    "five joints": lambda p: _rewrite(p, lambda r: _with(r, per_joint_rmse=(r["row"]["per_joint_rmse"] or [0.0] * 6)[:5])),
    "an extra field": lambda p: _rewrite(p, lambda r: _with(r, extra=1)),
    "video PSNR strings": lambda p: _rewrite(p, lambda r: _video(r, ["x"] * 3)),
    "video PSNR NaN": lambda p: _rewrite(p, lambda r: _video(r, [float("nan")] * 3)),
    "video of a view it lacks": lambda p: _rewrite(p, lambda r: {"row": None, "video": {
        **r["video"], "top": {**r["video"]["front"], "view": "top"}}}),
    "a number edited": lambda p: p.write_bytes(p.read_bytes().replace(b'"rmse_deg": ', b'"rmse_deg": 1', 1)),
    "truncated": lambda p: p.write_bytes(p.read_bytes()[:-100]),
    "another rollout's": lambda p: p.write_bytes(next(q for q in entry_files(p.parents[2]) if q != p).read_bytes()),
}


# Each report run corrupts the three rollouts' entries three different ways: a corruption read as
# an entry would change that rollout's row (or leave its file unwritten), so each is still checked
# on its own, in four runs of the command instead of eleven. Another rollout's entry goes first,
# while the others are still valid.
_ORDER = ["another rollout's", *sorted(set(CORRUPTIONS) - {"another rollout's"})]
CORRUPTION_GROUPS = [_ORDER[i:i + len(ROLLOUTS)] for i in range(0, len(_ORDER), len(ROLLOUTS))]


def test_the_groups_hold_every_corruption_once() -> None:
    assert sorted(c for group in CORRUPTION_GROUPS for c in group) == sorted(CORRUPTIONS)


@pytest.mark.parametrize("corruptions", CORRUPTION_GROUPS, ids=[" + ".join(g) for g in CORRUPTION_GROUPS])
def test_a_bad_entry_is_recomputed_rewritten_and_the_report_is_no_cache_s(
        corruptions: list[str], session: Path, warm_cache: Path, no_cache_report: str, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    shutil.copytree(warm_cache, cache)
    originals = {p.name: p.read_bytes() for p in entry_files(cache)}
    for corruption, path in zip(corruptions, entry_files(cache)):
        CORRUPTIONS[corruption](path)
        assert path.read_bytes() != originals[path.name], corruption
    # in this process (no pool to start): the entries were written by the warm cache's workers
    out = inspector("report", session, "--json", "--jobs", "1", cache=cache)
    assert out.returncode == 0 and out.stderr == "", out.stderr
    assert out.stdout == no_cache_report
    for path in entry_files(cache):  # written anew, as the first report wrote it
        assert read_back(path) is not None and path.read_bytes() == originals[path.name], path


def test_export_reads_around_bad_video_metrics(session: Path, warm_cache: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    shutil.copytree(warm_cache, cache)
    for path in entry_files(cache):
        CORRUPTIONS["video PSNR strings"](path)
    out = inspector("export", session, "--rollout", "single_f000", "-o", tmp_path / "b.rrd", cache=cache)
    assert out.returncode == 0 and out.stderr == "", out.stderr
    assert out.stdout.startswith(f"wrote {tmp_path / 'b.rrd'} (") and out.stdout.count("\n") == 1


# ----------------------------------------------------------------------------------------------
# A cache that cannot be used: one warning per command; an output that cannot be written: named


def _can_mount() -> bool:
    if shutil.which("unshare") is None:
        return False
    probe = subprocess.run(["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"],
                           capture_output=True)
    return probe.returncode == 0


needs_mount = pytest.mark.skipif(not _can_mount(), reason="cannot mount a tmpfs in a private mount namespace")

# Mounts a tmpfs at $MNT (with a cache directory), fills it or remounts it read-only, then runs the
# command, its stdout into $OUT when set; all in a private mount namespace, gone with the command.
_ON_TMPFS = """set -e
mount -t tmpfs -o size=256k tmpfs "$MNT"
mkdir "$MNT/cache"
if [ "$FILL" = 1 ]; then dd if=/dev/zero of="$MNT/fill" bs=4k 2>/dev/null || true; fi
if [ "$READ_ONLY" = 1 ]; then mount -o remount,ro "$MNT"; fi
if [ -n "$OUT" ]; then exec "$@" > "$OUT"; else exec "$@"; fi
"""


def on_tmpfs(mnt: Path, state: str, *args: Any, out: str = "") -> subprocess.CompletedProcess:
    """``inspector ARGS`` with ``$INSPECTOR_CACHE_DIR`` on a tmpfs at ``mnt`` that is ``full`` or ``read-only``."""
    mnt.mkdir(exist_ok=True)
    env = {"MNT": str(mnt), "FILL": str(int(state == "full")), "READ_ONLY": str(int(state == "read-only")),
           "OUT": out}
    return inspector(*args, cache=mnt / "cache", env=env, wrap=["unshare", "-rm", "sh", "-c", _ON_TMPFS, "sh"])


UNUSABLE = ["a file", pytest.param("read-only", marks=needs_mount), pytest.param("full", marks=needs_mount)]


def _jobs(state: str) -> str:
    """Two workers where the cache is a file (a state every machine can make), each failing to
    write its entry and handing its warning back: the command still prints one. The file systems'
    own failures (read-only, full) in the command's process: how a warning travels from a worker
    does not depend on why the write failed, and no pool of fresh interpreters (each decimating the
    arm's meshes again, with no cache to keep them) is started for it."""
    return "2" if state == "a file" else "1"


def _unusable(state: str, tmp_path: Path, *args: Any) -> subprocess.CompletedProcess:
    if state == "a file":
        (tmp_path / "cache-file").write_text("not a directory")
        return inspector(*args, cache=tmp_path / "cache-file")
    return on_tmpfs(tmp_path / "mnt", state, *args)


def _one_warning(out: subprocess.CompletedProcess) -> None:
    lines = out.stderr.splitlines()
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith("warning: cache ") and lines[0].endswith("; continuing without it"), lines


@pytest.mark.parametrize("state", UNUSABLE)
def test_report_with_an_unusable_cache_warns_once(state: str, small_session: Path, small_no_cache_report: str,
                                                  tmp_path: Path):
    out = _unusable(state, tmp_path, "report", small_session, "--json", "--jobs", _jobs(state))
    assert out.returncode == 0, out.stderr
    _one_warning(out)
    assert out.stdout == small_no_cache_report


@pytest.mark.parametrize("state", UNUSABLE)
def test_export_with_an_unusable_cache_warns_once_and_writes(state: str, small_session: Path, tmp_path: Path):
    out = _unusable(state, tmp_path, "export", small_session, "-o", tmp_path / "rrd", "--jobs", _jobs(state))
    assert out.returncode == 0, out.stderr
    _one_warning(out)
    assert sorted(p.name for p in (tmp_path / "rrd").iterdir()) == sorted(f"{t}.rrd" for t in SMALL)
    assert out.stdout.count("wrote ") == len(SMALL)


@needs_mount
@pytest.mark.parametrize("output", ["stdout", "--html", "-o"])
def test_an_output_that_cannot_be_written_is_named(output: str, session: Path, tmp_path: Path):
    """The output on a full disk: one line naming it, never ``-``, and exit 2. Of the one-chunk
    rollout: what is written does not matter, only where."""
    mnt = tmp_path / "mnt"
    one = session / "rollouts" / "single_f000"
    if output == "stdout":
        target, out = mnt / "report.json", on_tmpfs(mnt, "full", "report", one, "--json", "--no-cache",
                                                    out=str(mnt / "report.json"))
        what = "cannot write the output"
    elif output == "--html":
        target = mnt / "page.html"
        out = on_tmpfs(mnt, "full", "report", one, "--html", target, "--no-cache")
        what = "cannot write the page"
    else:
        target = mnt / "b.rrd"
        out = on_tmpfs(mnt, "full", "export", session, "--rollout", "single_f000", "-o", target, "--no-cache")
        what = "cannot write the recording"
    assert out.returncode == 2, out.stderr
    errors = [line for line in out.stderr.splitlines() if line.startswith("error:")]
    assert errors == [f"error: {target}: {what} (No space left on device)"], out.stderr
    assert len(out.stderr.splitlines()) <= 2  # and at most the cache's one warning


def test_the_schema_check_says_where_a_value_departs(warm_cache: Path) -> None:
    """What :func:`inspector.schema.mismatch` accepts and how it names what it refuses."""
    record = read_back(entry_files(warm_cache)[0])
    assert record is not None and mismatch(record, MetricsEntry) is None
    row = record["row"]
    cases = {
        "row: an object (RolloutRow) expected, got 5": {**record, "row": 5},
        "row.rmse_deg: a finite float expected, got '3'": {**record, "row": {**row, "rmse_deg": "3"}},
        "row.per_joint_rmse: 6 items expected, got 5": {**record, "row": {**row, "per_joint_rmse": [1.0] * 5}},
        "row.limit_violations.count: an integer expected, got True": {**record, "row": {
            **row, "limit_violations": {**row["limit_violations"], "count": True}}},
        "row.tempo: a finite float expected, got inf": {**record, "row": {**row, "tempo": float("inf")}},
        "row: an unknown key 'extra'": {**record, "row": {**row, "extra": 1}},
        "row: its keys out of order": {**record, "row": dict(reversed(row.items()))},
        "row.kind: one of ('single_chunk', 'autoregressive', 'open_loop_replay', 'episode') expected, got 'x'": {
            **record, "row": {**row, "kind": "x"}},
    }
    for expected, value in cases.items():
        assert mismatch(value, MetricsEntry) == expected


def test_joint_coherence_without_a_joints_offset_is_a_miss(warm_cache: Path) -> None:
    """Its readers look up the offset of every joint they call out of phase: an entry without
    one (a joint dropped, or its offset null) is inconsistent, never read."""
    from inspector.rows.entries import is_consistent
    from inspector.units import JOINT_NAMES

    coherent = [e for e in map(read_back, entry_files(warm_cache)) if e and e["row"] and e["row"]["joint_coherence"]]
    assert coherent, "no cached row with joint coherence"
    for entry in coherent:
        assert is_consistent(entry)
        j = entry["row"]["joint_coherence"]
        for joint in JOINT_NAMES:
            dropped = {**j, "phase_offset_steps": {k: v for k, v in j["phase_offset_steps"].items() if k != joint}}
            nulled = {**j, "phase_offset_steps": {**j["phase_offset_steps"], joint: None}, "out_of_phase": [joint]}
            for broken in (dropped, nulled):
                assert not is_consistent({**entry, "row": {**entry["row"], "joint_coherence": broken}}), joint
