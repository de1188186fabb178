"""Malformed input, made from valid inputs by mutation, for ``import``, ``info``, ``report``,
``export`` and the app's catalog (the property tests of the readers are in
``test_bad_input_properties.py``). The valid inputs are the repository's own: a DreamZero-SO101
source directory made from the bundled demo (``dreamzero_layout.py``), the sessions imported from
it, and the LeRobot-written datasets of ``tests/data/lerobot``.

What "bad input" means, per command (the same words are in ``inspector/cli/__init__.py``):

- ``import``: all or nothing. Any unreadable source rollout (or dataset, with ``--dataset``) is
  exit 2 with one line ``error: <file>: <what>``; nothing is written (no session, no
  ``.<dest>.*.partial`` sibling, no temporary directory).
- ``info``: describes PATH. Exit 2 when PATH itself cannot be read (``session.json``, a dataset's
  ``meta/`` files, a rollout directory named directly). A session's broken rollouts are listed
  under ``errors`` with exit 0.
- ``report``: exit 2 when a path is unusable or nothing could be reported (no rollouts, or every one
  broken); otherwise exit 0 with the broken rollouts under ``errors``.
- ``export``: writes every rollout it can; each broken rollout prints its own ``error:`` line,
  leaves no file (no ``.rrd``, no ``.partial``) and makes the exit code 2.
- app: a broken rollout is an entry with an error (an error card); ``Catalog.load`` raises only
  ``InspectorError``; the other rollouts load.

Not errors: a rollout longer than its episode (its late chunks are "post-episode"), joint values
far outside the limits (1e30 still reports; only beyond ``ABSURD_VALUE`` = 1e100, where the
metrics' squared distances would overflow, is a value refused), a dataset that a session names but
that is gone (the rollouts simply have no dataset GT), two source directories with the same name.

Every CLI case runs ``inspector`` as a process of its own with its own ``TMPDIR`` (which must be
empty afterwards), forked from a process that imported the CLI once (``cli_processes.py``); the
cases run side by side from one module-scoped fixture.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_processes import CommandServer

from inspector.data.session import SessionWriter, open_session
from inspector.errors import InspectorError
from inspector.units import JOINT_NAMES

pytestmark = pytest.mark.slow  # every malformed case run through the CLI as a process

SIDE_BY_SIDE = 3  # cases running at once (their start-up is shared, so the cores are busy)
# The report and export cases run their rollouts in the command's own process (``--jobs 1``):
# spawning a pool of workers costs each case seconds of start-up, and what is malformed is found
# the same way in either. These keep the default pool, so that errors raised in workers and
# carried back to the command are covered too.
IN_WORKERS = frozenset({"report-one-npy-truncated", "report-dataset-video-corrupt", "export-video-corrupt",
                        "export-one-bad-of-three"})

# ==============================================================================================
# Mutation helpers


def copy_tree(src: Path, dst: Path) -> Path:
    """Copy a (read-only) fixture tree so that it can be mutated."""
    shutil.copytree(src, dst, copy_function=shutil.copyfile)
    for p in [dst, *dst.rglob("*")]:
        os.chmod(p, 0o755 if p.is_dir() else 0o644)
    return dst


def edit_json(path: Path, **fields: Any) -> None:
    data = json.loads(path.read_text())
    data.update(fields)
    path.write_text(json.dumps(data))


def drop_json_key(path: Path, key: str) -> None:
    data = json.loads(path.read_text())
    del data[key]
    path.write_text(json.dumps(data))


def truncate(path: Path, keep: float = 0.5) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def corrupt_middle(path: Path, n: int = 2000, at: float = 0.5) -> None:
    """Zero ``n`` bytes at fraction ``at`` of the file: the container still opens, the stream does
    not decode there."""
    data = bytearray(path.read_bytes())
    mid = int(len(data) * at)
    data[mid:mid + n] = bytes(len(data[mid:mid + n]))
    path.write_bytes(bytes(data))


def npy_bytes(descr: str, shape: tuple, payload: bytes, fortran_order: bool = False) -> bytes:
    """A hand-made ``.npy`` (format 1.0) with any header, valid or not."""
    header = f"{{'descr': {descr!r}, 'fortran_order': {fortran_order!r}, 'shape': {shape!r}, }}".encode("latin1")
    pad = (-(10 + len(header) + 1)) % 64
    header += b" " * pad + b"\n"
    return b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + payload


DEEP_JSON = "[" * 100_000  # json.loads -> RecursionError
HUGE_INT_JSON = '{"fps": 1' + "0" * 5000 + "}"  # json.loads -> ValueError (int digit limit)


def set_parquet_column(path: Path, column: str, fn: Callable[[list], list], variable_list: bool = False) -> None:
    """Rewrite one column of a parquet file (``variable_list``: as a list<float32>, any length)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    col = table.column(column)
    values = fn(col.to_pylist())
    typ = pa.list_(pa.float32()) if variable_list else col.type
    table = table.set_column(table.column_names.index(column), column, pa.array(values, type=typ))
    pq.write_table(table, path)


def nan_row(rows: list) -> list:
    rows = [list(r) for r in rows]
    rows[5][2] = float("nan")
    return rows


# ==============================================================================================
# Workspace: valid inputs built once, copied per case


class Workspace:
    """Valid inputs (built once per module) that each case copies into its own directory."""

    def __init__(self, root: Path, dz_source: Path, lerobot: Path) -> None:
        """``dz_source``: a DreamZero-SO101 source directory (``dreamzero_layout.py``, made from
        the demo); ``lerobot``: the folder of the LeRobot-written datasets (``tests/data/lerobot``)."""
        from inspector.data.importers.dreamzero_so101 import import_dreamzero

        self.root, self.lerobot, self.dz = root, lerobot, dz_source
        base = root / "base"
        # three single-chunk rollouts (f000, f076, f153): "one bad rollout of several"
        self.zs3 = import_dreamzero(self.dz / "zeroshot_chunk", base / "zs3", log=lambda _: None)
        # one single-chunk rollout: "the only rollout is bad"
        self.zs1 = import_dreamzero(self.dz / "zeroshot_chunk" / "f076", base / "zs1", log=lambda _: None)
        self.v30 = copy_tree(lerobot / "so101_v30", base / "so101_v30")
        self.ds = self.dataset_session(base / "ds", self.v30)

    @staticmethod
    def dataset_session(dest: Path, dataset: Path, long: bool = False) -> Path:
        """A session whose GT comes from a LeRobot dataset (episodes of 150 and 210 frames)."""
        rng = np.random.default_rng(0)
        with SessionWriter.create(dest, dataset=dataset, model={"name": "test"}) as w:
            w.add_rollout("r0", kind="autoregressive", actions=rng.normal(0, 5, (2, 24, 6)),
                          episode_index=0, start_frame=0, prompt="Pick the red cube")
            w.add_rollout("r1", kind="autoregressive", actions=rng.normal(0, 5, (2, 24, 6)),
                          episode_index=1, start_frame=0,
                          # 4:3, as the dataset's camera (frames of another geometry are not compared)
                          videos={"front": rng.integers(0, 255, (18, 36, 48, 3), dtype=np.uint8)})
            if long:  # 20 chunks x 9 = 180 steps in a 150-frame episode: 3 chunks start after it
                w.add_rollout("long", kind="autoregressive", actions=rng.normal(0, 5, (20, 24, 6)),
                              episode_index=0, start_frame=0)
                # from frame 140 of 150: 10 steps inside, the third chunk starts after the end
                w.add_rollout("late", kind="autoregressive", actions=rng.normal(0, 5, (3, 24, 6)),
                              episode_index=0, start_frame=140)
        return dest

    # -- copies for one case ------------------------------------------------------------------
    def session(self, case: Path, which: str = "zs3") -> Path:
        return copy_tree(getattr(self, which), case / which)

    def ds_session(self, case: Path, dataset: Path | None = None) -> Path:
        s = copy_tree(self.ds, case / "ds")
        if dataset is not None:
            edit_json(s / "session.json", gt_source={"dataset": str(dataset)})
        return s

    def source(self, case: Path, rel: str) -> Path:
        """A DreamZero-SO101 source directory, e.g. ``zeroshot_chunk/f076``."""
        return copy_tree(self.dz / rel, case / "src" / Path(rel).name)

    def dataset(self, case: Path, name: str = "so101_v30") -> Path:
        return copy_tree(self.lerobot / name, case / name)


AR, SC, MOSAIC = "train_rollout/ep000_train", "zeroshot_chunk/f076", "demo/train_ep0"
F076 = "rollouts/f076"
V30_DATA = "data/chunk-000/file-000.parquet"
V30_FRONT = "videos/observation.images.front/chunk-000/file-000.mp4"


# ==============================================================================================
# The cases


@dataclass(frozen=True)
class Case:
    """One malformed input and what the command must do with it.

    Attributes:
        build: ``build(ws, case_dir) -> argv`` makes the input under ``case_dir`` and returns the
            arguments after ``inspector``; outputs go under ``case_dir / "out"`` (created empty).
        rc: expected exit code.
        file: a piece of the path the error must name (``None``: no error expected).
        field: words the error must contain after the file (the field, or what is wrong).
        out: what ``case_dir / "out"`` must hold afterwards (names, hidden ones included).
        check: extra assertions on the finished run.
    """

    id: str
    build: Callable[[Workspace, Path], list[Any]]
    rc: int = 2
    file: str | None = None
    field: str | None = None
    out: tuple[str, ...] = ()
    check: Callable[[Run], None] | None = None


@dataclass
class Run:
    case: Case
    dir: Path
    rc: int
    stdout: str
    stderr: str

    def json(self) -> Any:
        return json.loads(self.stdout)


def _import(ws: Workspace, d: Path, rel: str, mutate: Callable[[Path], Any], *extra: Any) -> list[Any]:
    src = ws.source(d, rel)
    mutate(src)
    return ["import", "dreamzero-so101", src, "-o", d / "out" / "session", *extra]


def _imp(id: str, rel: str, mutate: Callable[[Path], Any], file: str, field: str, *extra: Any) -> Case:
    return Case(id, lambda ws, d: _import(ws, d, rel, mutate, *extra), file=file, field=field)


def _session_cmd(cmd: str, which: str, mutate: Callable[[Path], Any], *extra: Any,
                 sub: str = "") -> Callable[[Workspace, Path], list[Any]]:
    def build(ws: Workspace, d: Path) -> list[Any]:
        s = ws.session(d, which)
        mutate(s)
        return [cmd, s / sub if sub else s, *extra]
    return build


def _export_cmd(which: str, mutate: Callable[[Path], Any], *extra: Any, out: str = "x.rrd"):
    def build(ws: Workspace, d: Path) -> list[Any]:
        s = ws.session(d, which)
        mutate(s)
        return ["export", s, "-o", d / "out" / out if out else d / "out", *extra]
    return build


def _ds_cmd(cmd: str, mutate: Callable[[Workspace, Path, Path], Any], *extra: Any):
    def build(ws: Workspace, d: Path) -> list[Any]:
        s = ws.ds_session(d)
        mutate(ws, d, s)
        return [cmd, s, *extra]
    return build


def _dataset_cmd(name: str, mutate: Callable[[Path], Any]):
    def build(ws: Workspace, d: Path) -> list[Any]:
        ds = ws.dataset(d, name)
        mutate(ds)
        return ["info", ds]
    return build


def _listed_error(key_suffix: str, file: str, field: str) -> Callable[[Run], None]:
    """Exit 0, and the JSON output's ``errors`` has the rollout, naming file and field."""
    def check(run: Run) -> None:
        errors = run.json().get("errors", {})
        hits = [v for k, v in errors.items() if k.endswith(key_suffix)]
        assert len(hits) == 1, errors
        assert file in hits[0].split(": ", 1)[0] and field in hits[0], hits[0]
        assert "\n" not in hits[0]
    return check


def _rows(tags: list[str]) -> Callable[[Run], None]:
    def check(run: Run) -> None:
        assert sorted(r["tag"] for r in run.json()["rollouts"]) == sorted(tags)
    return check


def _warned_rows(tags: list[str], warning: str) -> Callable[[Run], None]:
    def check(run: Run) -> None:
        report = run.json()
        assert sorted(r["tag"] for r in report["rollouts"]) == sorted(tags)
        assert [w for w in report["warnings"] if w.startswith(warning)], report["warnings"]
    return check


def _ok_report_rows(tags: list[str], key_suffix: str, file: str, field: str) -> Callable[[Run], None]:
    def check(run: Run) -> None:
        _rows(tags)(run)
        _listed_error(key_suffix, file, field)(run)
    return check


def _check_long(run: Run) -> None:
    rows = {r["tag"]: r for r in run.json()["rollouts"]}
    assert rows["long"]["post_episode_chunks"] == 3 and rows["long"]["time_aligned_drift"] is not None
    assert rows["late"]["post_episode_chunks"] == 1
    assert rows["r0"]["post_episode_chunks"] == 0 and "errors" not in run.json()


def _check_table_lists_error(run: Run) -> None:
    """The text report shows the good rollouts and one ``error:`` line for the broken one."""
    lines = run.stdout.splitlines()
    assert any(line.startswith("f000 ") for line in lines) and any(line.startswith("f153 ") for line in lines)
    errors = [line for line in lines if line.startswith("error: ")]
    assert len(errors) == 1 and "f076/actions.npy" in errors[0] and "not a readable .npy" in errors[0]


def _check_absurd_1e30(run: Run) -> None:
    (row,) = run.json()["rollouts"]
    assert row["rmse_deg"] > 1e29 and row["limit_violations"]["count"] == 24 * 6


def _check_no_dataset_gt(run: Run) -> None:
    rows = run.json()["rollouts"]
    # the session names a dataset that is gone: no GT joints, and the report says why
    assert all(r["gt_source"].startswith("none (dataset ") and r["gt_source"].endswith(" not found)") for r in rows)
    assert len(rows) == 2 and all(r["rmse_deg"] is None for r in rows)


def _check_dest_untouched(run: Run) -> None:
    assert (run.dir / "out" / "session" / "keep.txt").read_text() == "mine"


def _check_duplicate_tags(run: Run) -> None:
    s = open_session(run.dir / "out" / "session")
    assert sorted(s.rollouts) == ["b_f076", "f076"] and not s.errors


def _mk_empty(d: Path) -> None:
    for p in list(d.iterdir()):
        shutil.rmtree(p) if p.is_dir() else p.unlink()


def _two_same_name(ws: Workspace, d: Path) -> list[Any]:
    src = d / "src"
    copy_tree(ws.dz / SC, src / "a" / "f076")
    copy_tree(ws.dz / SC, src / "b" / "f076")
    return ["import", "dreamzero-so101", src, "-o", d / "out" / "session"]


def _dest_exists(ws: Workspace, d: Path) -> list[Any]:
    (d / "out" / "session").mkdir()
    (d / "out" / "session" / "keep.txt").write_text("mine")
    return ["import", "dreamzero-so101", ws.source(d, SC), "-o", d / "out" / "session"]


def _dest_under_file(ws: Workspace, d: Path) -> list[Any]:
    (d / "out" / "file").write_text("x")
    return ["import", "dreamzero-so101", ws.source(d, SC), "-o", d / "out" / "file" / "session"]


def _overwrite_onto(kind: str) -> Callable[[Workspace, Path], list[Any]]:
    """``import --overwrite`` onto what is at ``out/session``: a directory of the user's files,
    a regular file, or a session (the only thing ``--overwrite`` may replace)."""
    def build(ws: Workspace, d: Path) -> list[Any]:
        dest = d / "out" / "session"
        if kind == "directory":
            dest.mkdir()
            (dest / "keep.txt").write_text("mine")
        elif kind == "file":
            dest.write_text("mine")
        else:
            copy_tree(ws.zs3, dest)
        return ["import", "dreamzero-so101", ws.source(d, SC), "-o", dest, "--overwrite"]
    return build


def _check_file_untouched(run: Run) -> None:
    assert (run.dir / "out" / "session").read_text() == "mine"


def _check_session_replaced(run: Run) -> None:
    s = open_session(run.dir / "out" / "session")
    assert sorted(s.rollouts) == ["f076"] and not s.errors  # the old session's f000, f153 are gone


# a newline, an escape sequence (a terminal colour) and a Unicode line separator
CONTROL_NAME = "ep\n000\x1b[31m\u2028"
CONTROL_NAME_ESCAPED = r"ep\n000\x1b[31m\u2028"  # as the error line writes it


def _control_chars_in_path(ws: Workspace, d: Path) -> list[Any]:
    src = copy_tree(ws.dz / AR, d / "src" / CONTROL_NAME)
    truncate(src / _AR_TRACE)
    return ["import", "dreamzero-so101", src, "-o", d / "out" / "session"]


NON_ASCII_NAME, LONG_NAME = "épisode_日本", "a" * 250


def _odd_source_names(ws: Workspace, d: Path) -> list[Any]:
    copy_tree(ws.dz / SC, d / "src" / NON_ASCII_NAME)
    copy_tree(ws.dz / "zeroshot_chunk" / "f153", d / "src" / LONG_NAME)
    return ["import", "dreamzero-so101", d / "src", "-o", d / "out" / "session"]


def _check_odd_source_names(run: Run) -> None:
    from inspector.data.session import _TAG

    s = open_session(run.dir / "out" / "session")
    assert not s.errors and len(s.rollouts) == 2
    names = {tag: r.extra["source"]["name"] for tag, r in s.rollouts.items()}
    assert all(_TAG.match(tag) and len(tag) <= 128 for tag in names), names
    assert sorted(names.values()) == sorted([NON_ASCII_NAME, LONG_NAME])  # the original names are kept
    assert names.get("episode") == NON_ASCII_NAME, names


def _report_long_named_source(ws: Workspace, d: Path) -> list[Any]:
    return ["report", copy_tree(ws.dz / SC, d / "src" / LONG_NAME), "--json"]


def _check_long_named_report(run: Run) -> None:
    (row,) = run.json()["rollouts"]
    assert row["tag"] == "a" * 119 + "_" + row["tag"][-8:]


def _import_with_dataset(rel: str, mutate_ds: Callable[[Path], Any], *extra: Any):
    def build(ws: Workspace, d: Path) -> list[Any]:
        ds = ws.dataset(d)
        mutate_ds(ds)
        return ["import", "dreamzero-so101", ws.source(d, rel), "-o", d / "out" / "session",
                "--dataset", ds, *extra]
    return build


def _ds_with_broken_dataset(mutate: Callable[[Path], Any], cmd: str = "report"):
    """The dataset session pointed at a copy of the dataset that ``mutate`` breaks."""
    def build(ws: Workspace, d: Path) -> list[Any]:
        ds = ws.dataset(d)
        mutate(ds)
        return [cmd, ws.ds_session(d, dataset=ds), "--json"]
    return build


def _long_rollouts(ws: Workspace, d: Path) -> list[Any]:
    return ["report", Workspace.dataset_session(d / "long", ws.v30, long=True), "--json"]


def _raw_source_report(ws: Workspace, d: Path) -> list[Any]:
    src = ws.source(d, SC)
    edit_json(src / "meta.json", actions_gt=[[1.0] * 6] * 3)
    return ["report", src]


def _same_session_twice(ws: Workspace, d: Path) -> list[Any]:
    s = ws.session(d, "zs1")
    return ["report", s, s, "--json"]


def _report_dataset_arg_broken(ws: Workspace, d: Path) -> list[Any]:
    (d / "notads").mkdir()
    return ["report", ws.session(d, "zs1"), "--dataset", d / "notads"]


def _info_rollout_path(ws: Workspace, d: Path) -> list[Any]:
    s = ws.session(d, "zs3")
    np.save(s / F076 / "actions.npy", np.zeros((1, 24, 4)))
    return ["info", s / F076]


def _save(rel: str, arr: Any, **kw: Any) -> Callable[[Path], None]:
    return lambda root: np.save(root / rel, arr, **kw)


def _scale_actions(root: Path, value: float, rel: str = F076 + "/actions.npy") -> None:
    a = np.load(root / rel)
    np.save(root / rel, np.full_like(a, value))


_AR_TRACE = "action_trace.npy"

CASES: list[Case] = [
    # ---------------------------------------------------------------- import: .npy
    _imp("import-npy-truncated", AR, lambda s: truncate(s / _AR_TRACE), "action_trace.npy", "not a readable .npy"),
    _imp("import-npy-bad-header", AR, lambda s: (s / _AR_TRACE).write_bytes(npy_bytes("zz", (60, 24, 6), b"")),
         "action_trace.npy", "not a readable .npy"),
    _imp("import-npy-dtype-str", AR, _save(_AR_TRACE, np.full((60, 24, 6), "a")), "action_trace.npy", "dtype <U1"),
    _imp("import-npy-dtype-complex", AR, _save(_AR_TRACE, np.zeros((60, 24, 6), complex)),
         "action_trace.npy", "dtype complex128"),
    _imp("import-npy-object-pickle", AR, _save(_AR_TRACE, np.zeros((60, 24, 6), object), allow_pickle=True),
         "action_trace.npy", "allow_pickle"),
    _imp("import-npy-nan", AR, lambda s: np.save(s / _AR_TRACE, np.where(np.arange(6) == 2, np.nan, np.load(s / _AR_TRACE))),
         "action_trace.npy", "non-finite value nan at index [0, 0, 2]"),
    _imp("import-state-inf", AR, _save("state_trace.npy", np.full((61, 6), np.inf)), "state_trace.npy", "non-finite"),
    _imp("import-npy-5-joints", AR, lambda s: np.save(s / _AR_TRACE, np.load(s / _AR_TRACE)[..., :5]),
         "action_trace.npy", "shape: expected (n_chunks, horizon, 6), found (60, 24, 5)"),
    _imp("import-state-chunk-count-mismatch", AR, _save("state_trace.npy", np.zeros((59, 6))),
         "state_trace.npy", "shape: expected (61, 6), found (59, 6)"),
    _imp("import-zero-chunks", AR, _save(_AR_TRACE, np.zeros((0, 24, 6))), "action_trace.npy", "no chunks"),
    _imp("import-absurd-1e300", AR, lambda s: np.save(s / _AR_TRACE, np.full((60, 24, 6), 1e300)),
         "action_trace.npy", "absurd value 1e+300"),
    # ---------------------------------------------------------------- import: meta.json
    _imp("import-meta-invalid-json", AR, lambda s: (s / "meta.json").write_text('{"episode": 0,'),
         "meta.json", "invalid JSON"),
    _imp("import-meta-not-object", AR, lambda s: (s / "meta.json").write_text("[1, 2]"),
         "meta.json", "expected a JSON object, found list"),
    _imp("import-meta-not-utf8", AR, lambda s: (s / "meta.json").write_bytes(b"\xff\xfe{garbage"),
         "meta.json", "invalid JSON"),
    _imp("import-meta-deeply-nested", SC, lambda s: (s / "meta.json").write_text(DEEP_JSON),
         "meta.json", "invalid JSON (RecursionError"),
    _imp("import-meta-huge-int", AR, lambda s: (s / "meta.json").write_text(HUGE_INT_JSON),
         "meta.json", "invalid JSON"),
    _imp("import-frames-per-step-zero", AR, lambda s: edit_json(s / "meta.json", frames_per_step=0),
         "meta.json", "frames_per_step: 0 must lie in 1..24"),
    _imp("import-frames-per-step-string", AR, lambda s: edit_json(s / "meta.json", frames_per_step="9"),
         "meta.json", "frames_per_step: expected a non-negative integer"),
    _imp("import-episode-negative", AR, lambda s: edit_json(s / "meta.json", episode=-3), "meta.json", "episode:"),
    _imp("import-prompt-not-string", AR, lambda s: edit_json(s / "meta.json", prompt=5), "meta.json", "prompt:"),
    _imp("import-episode-length-string", AR, lambda s: edit_json(s / "meta.json", episode_length="x"),
         "meta.json", "episode_length: expected a positive integer"),
    _imp("import-sc-actions-nan", SC, lambda s: edit_json(s / "meta.json", actions_pred=[[float("nan")] * 6] * 24),
         "meta.json", "actions_pred[0][0]: non-finite number nan"),
    _imp("import-sc-actions-ragged", SC, lambda s: edit_json(s / "meta.json", actions_pred=[[1] * 6] * 23 + [[1] * 5]),
         "meta.json", "actions_pred: expected a (horizon, 6) list of numbers"),
    _imp("import-sc-actions-missing-key", SC, lambda s: drop_json_key(s / "meta.json", "actions_pred"),
         "f076", "no DreamZero-SO101 rollout found"),
    _imp("import-sc-gt-shape-mismatch", SC, lambda s: edit_json(s / "meta.json", actions_gt=[[1] * 6] * 12),
         "meta.json", "actions_gt: shape (12, 6) differs"),
    _imp("import-sc-predicted-frames-zero", SC, lambda s: edit_json(s / "meta.json", predicted_frames=0),
         "meta.json", "predicted_frames: must be >= 1"),
    _imp("import-meta-nan", SC, lambda s: edit_json(s / "meta.json", video_psnr_db=float("nan")),
         "meta.json", "video_psnr_db: non-finite number nan"),
    _imp("import-meta-infinity-in-a-list", SC,
         lambda s: edit_json(s / "meta.json", per_joint_rmse=[1.0, 2.0, float("-inf")]),
         "meta.json", "per_joint_rmse[2]: non-finite number -inf"),
    _imp("import-meta-state-nan", AR, lambda s: edit_json(s / "meta.json", initial_state=[float("nan")] * 6),
         "meta.json", "initial_state[0]: non-finite number nan"),
    # ---------------------------------------------------------------- import: video
    _imp("import-video-truncated", AR, lambda s: truncate(s / "rollout_front.mp4"), "rollout_front.mp4", "cannot read video"),
    _imp("import-video-not-a-video", AR, lambda s: (s / "rollout_front.mp4").write_text("not a video"),
         "rollout_front.mp4", "cannot read video"),
    _imp("import-sc-pred-video-truncated", SC, lambda s: truncate(s / "pred_gripper.mp4", 0.3), "pred_gripper.mp4",
         "cannot read video"),
    _imp("import-mosaic-truncated", MOSAIC, lambda s: truncate(s / "gt_future.mp4"), "gt_future.mp4", "cannot read video"),
    # ---------------------------------------------------------------- import: paths, dataset
    Case("import-empty-source-dir", lambda ws, d: ["import", "dreamzero-so101", (d / "empty").mkdir() or d / "empty",
                                                   "-o", d / "out" / "session"],
         file="empty", field="no DreamZero-SO101 rollout found"),
    Case("import-missing-source", lambda ws, d: ["import", "dreamzero-so101", d / "nope", "-o", d / "out" / "session"],
         file="nope", field="not found"),
    Case("import-dest-exists", _dest_exists, file="out/session", field="already exists", out=("session",),
         check=_check_dest_untouched),
    Case("import-dest-under-a-file", _dest_under_file, file="out/file", field="File exists", out=("file",)),
    Case("import-overwrite-refuses-a-plain-directory", _overwrite_onto("directory"), file="out/session",
         field="is not a session (no session.json)", out=("session",), check=_check_dest_untouched),
    Case("import-overwrite-refuses-a-file", _overwrite_onto("file"), file="out/session",
         field="exists and is a file, not a session", out=("session",), check=_check_file_untouched),
    Case("import-overwrite-replaces-a-session", _overwrite_onto("session"), rc=0, out=("session",),
         check=_check_session_replaced),
    Case("import-control-characters-in-path", _control_chars_in_path, file=f"src/{CONTROL_NAME_ESCAPED}/action_trace.npy",
         field="not a readable .npy"),
    Case("import-non-ascii-and-long-source-names", _odd_source_names, rc=0, out=("session",),
         check=_check_odd_source_names),
    Case("report-raw-source-with-a-long-name", _report_long_named_source, rc=0, check=_check_long_named_report),
    Case("import-dataset-episode-beyond", _import_with_dataset(SC, lambda ds: None, "--episode", "9"),
         file="so101_v30", field="episode 9 is out of range"),
    Case("import-dataset-start-frame-beyond", _import_with_dataset("zeroshot_chunk/f153", lambda ds: None, "--episode", "0"),
         file="f153/meta.json", field="start frame 153 lies beyond episode 0 (150 frames)"),
    Case("import-dataset-unknown-version",
         _import_with_dataset(SC, lambda ds: edit_json(ds / "meta/info.json", codebase_version="v9.9"), "--episode", "0"),
         file="meta/info.json", field="codebase_version 'v9.9' is not supported"),
    Case("import-duplicate-tags-are-renamed", _two_same_name, rc=0, out=("session",), check=_check_duplicate_tags),
    # ---------------------------------------------------------------- info: session.json
    Case("info-session-invalid-json", _session_cmd("info", "zs3", lambda s: (s / "session.json").write_text("{")),
         file="session.json", field="invalid JSON"),
    Case("info-session-not-object", _session_cmd("info", "zs3", lambda s: (s / "session.json").write_text("null")),
         file="session.json", field="expected a JSON object"),
    Case("info-session-unknown-schema",
         _session_cmd("info", "zs3", lambda s: edit_json(s / "session.json", schema="inspector.session/9")),
         file="session.json", field="schema: expected 'inspector.session/1'"),
    Case("info-session-missing-schema", _session_cmd("info", "zs3", lambda s: drop_json_key(s / "session.json", "schema")),
         file="session.json", field="schema:"),
    Case("info-session-bad-units",
         _session_cmd("info", "zs3", lambda s: edit_json(s / "session.json", units={"arm": "radians"})),
         file="session.json", field="units.arm must be one of"),
    Case("info-session-five-joint-names",
         _session_cmd("info", "zs3", lambda s: edit_json(s / "session.json", joint_names=list(JOINT_NAMES[:5]))),
         file="session.json", field="joint_names: expected"),
    Case("info-session-dataset-not-a-string",
         _session_cmd("info", "zs3", lambda s: edit_json(s / "session.json", gt_source={"dataset": 5})),
         file="session.json", field="gt_source.dataset: expected a path string"),
    Case("info-extra-keys-are-ignored",
         _session_cmd("info", "zs3", lambda s: (edit_json(s / "session.json", future_field={"x": 1}),
                                                edit_json(s / F076 / "rollout.json", future_field=[1, 2])), "--json"),
         rc=0, check=_rows(["f000", "f076", "f153"])),
    Case("info-session-rollouts-is-a-file",
         _session_cmd("info", "zs3", lambda s: (shutil.rmtree(s / "rollouts"), (s / "rollouts").write_text("x"))),
         file="zs3/rollouts", field="expected a directory"),
    Case("info-empty-session-is-fine", _session_cmd("info", "zs3", lambda s: _mk_empty(s / "rollouts"), "--json"),
         rc=0, check=_rows([])),
    Case("info-one-bad-rollout-json-of-three",
         _session_cmd("info", "zs3", lambda s: (s / F076 / "rollout.json").write_text("{{"), "--json"),
         rc=0, check=_listed_error("f076", "f076/rollout.json", "invalid JSON")),
    Case("info-one-rollout-duplicate-views",
         _session_cmd("info", "zs3", lambda s: edit_json(s / F076 / "rollout.json", views=["front", "front"]), "--json"),
         rc=0, check=_listed_error("f076", "f076/rollout.json", "views: listed twice")),
    Case("info-one-rollout-negative-episode",
         _session_cmd("info", "zs3", lambda s: edit_json(s / F076 / "rollout.json", episode_index=-1), "--json"),
         rc=0, check=_listed_error("f076", "f076/rollout.json", "episode_index: must be >= 0")),
    Case("info-one-rollout-missing-video",
         _session_cmd("info", "zs3", lambda s: (s / F076 / "video" / "gripper.mp4").unlink(), "--json"),
         rc=0, check=_listed_error("f076", "f076/video/gripper.mp4", "imagined video for view 'gripper' not found")),
    Case("info-one-rollout-extra-states-rows",
         _session_cmd("info", "zs3", _save(F076 + "/states.npy", np.zeros((5, 6))), "--json"),
         rc=0, check=_listed_error("f076", "f076/states.npy", "shape: expected (2, 6), found (5, 6)")),
    Case("info-rollout-path-joint-count", _info_rollout_path, file="f076/actions.npy",
         field="shape: expected (n_chunks, 24, 6), found (1, 24, 4)"),
    Case("info-missing-path", lambda ws, d: ["info", d / "nowhere"], file="nowhere", field="not found"),
    # ---------------------------------------------------------------- info: datasets
    Case("info-dataset-info-invalid-json", _dataset_cmd("so101_v30", lambda ds: (ds / "meta/info.json").write_text("{,")),
         file="meta/info.json", field="invalid JSON"),
    Case("info-dataset-info-not-object", _dataset_cmd("so101_v30", lambda ds: (ds / "meta/info.json").write_text("[]")),
         file="meta/info.json", field="expected a JSON object"),
    Case("info-dataset-unknown-codebase-version",
         _dataset_cmd("so101_v30", lambda ds: edit_json(ds / "meta/info.json", codebase_version="v9.9")),
         file="meta/info.json", field="codebase_version 'v9.9' is not supported"),
    Case("info-dataset-missing-codebase-version",
         _dataset_cmd("so101_v30", lambda ds: drop_json_key(ds / "meta/info.json", "codebase_version")),
         file="meta/info.json", field="codebase_version None is not supported"),
    Case("info-dataset-total-episodes-nan",
         _dataset_cmd("so101_v30", lambda ds: (ds / "meta/info.json").write_text(
             (ds / "meta/info.json").read_text().replace('"total_episodes": 3', '"total_episodes": NaN'))),
         file="meta/info.json", field="'total_episodes' must be a non-negative number"),
    Case("info-dataset-five-joint-names",
         _dataset_cmd("so101_v30", lambda ds: edit_json(ds / "meta/info.json", features={
             **json.loads((ds / "meta/info.json").read_text())["features"],
             "action": {"dtype": "float32", "shape": [5], "names": ["a", "b", "c", "d", "e"]}})),
         file="meta/info.json", field="features.action.names: expected the 6 SO-101 joints"),
    Case("info-dataset-features-missing",
         _dataset_cmd("so101_v30", lambda ds: drop_json_key(ds / "meta/info.json", "features")),
         file="meta/info.json", field="'features' is missing or not an object"),
    Case("info-dataset-episodes-parquet-truncated",
         _dataset_cmd("so101_v30", lambda ds: truncate(ds / "meta/episodes/chunk-000/file-000.parquet")),
         file="meta/episodes/chunk-000/file-000.parquet", field="cannot read parquet"),
    Case("info-dataset-v21-episodes-bad-line",
         _dataset_cmd("so101_v21", lambda ds: (ds / "meta/episodes.jsonl").write_text('{"episode_index": 0, "length": "x"}\n')),
         file="meta/episodes.jsonl", field="line 1: needs integer 'episode_index' and 'length'"),
    Case("info-dataset-v21-negative-length",
         _dataset_cmd("so101_v21", lambda ds: (ds / "meta/episodes.jsonl").write_text('{"episode_index": 0, "length": -5}\n')),
         file="meta/episodes.jsonl", field="line 1: 'episode_index' must be >= 0 and 'length' >= 1"),
    Case("info-dataset-v21-episodes-not-utf8",
         _dataset_cmd("so101_v21", lambda ds: (ds / "meta/episodes.jsonl").write_bytes(b"\xff\xfe\x00")),
         file="meta/episodes.jsonl", field="cannot read"),
    # ---------------------------------------------------------------- report: the path is unusable
    Case("report-session-invalid-json", _session_cmd("report", "zs3", lambda s: (s / "session.json").write_text("{")),
         file="session.json", field="invalid JSON"),
    Case("report-session-dataset-nul-byte",
         _session_cmd("report", "zs3", lambda s: edit_json(s / "session.json", gt_source={"dataset": "a\x00b"})),
         file="session.json", field="gt_source.dataset"),
    Case("report-session-dataset-not-a-string",
         _session_cmd("report", "zs1", lambda s: edit_json(s / "session.json", gt_source={"dataset": 5})),
         file="session.json", field="gt_source.dataset: expected a path string, found 5"),
    Case("report-empty-session", _session_cmd("report", "zs3", lambda s: shutil.rmtree(s / "rollouts")),
         file="zs3", field="no rollouts to report"),
    Case("report-only-rollout-unknown-kind",
         _session_cmd("report", "zs1", lambda s: edit_json(s / F076 / "rollout.json", kind="multi")),
         file="f076/rollout.json", field="kind: expected one of"),
    Case("report-only-rollout-fps-huge-int",
         _session_cmd("report", "zs1", lambda s: edit_json(s / F076 / "rollout.json", fps=10 ** 400)),
         file="f076/rollout.json", field="fps: must be a finite number"),
    Case("report-only-rollout-json-huge-int",
         _session_cmd("report", "zs1", lambda s: (s / F076 / "rollout.json").write_text(HUGE_INT_JSON)),
         file="f076/rollout.json", field="invalid JSON"),
    Case("report-only-rollout-empty-gt-actions",
         _session_cmd("report", "zs1", _save(F076 + "/gt/actions.npy", np.zeros((0, 6)))),
         file="f076/gt/actions.npy", field="no GT steps"),
    Case("report-absurd-1e300", _session_cmd("report", "zs1", lambda s: _scale_actions(s, 1e300)),
         file="f076/actions.npy", field="absurd value 1e+300 at index [0, 0, 0]"),
    Case("report-bad-rollout-path", _session_cmd("report", "zs3", lambda s: truncate(s / F076 / "actions.npy"),
                                                 sub=F076),
         file="f076/actions.npy", field="not a readable .npy"),
    Case("report-raw-source-broken-leaves-no-temp", _raw_source_report, file="f076/meta.json",
         field="actions_gt: shape (3, 6) differs"),
    Case("report-unknown-user-path", lambda ws, d: ["report", "~nosuchuser_inspector/x"],
         file="~nosuchuser_inspector/x", field="not found"),
    Case("report-dataset-option-not-a-dataset", _report_dataset_arg_broken, file="notads/meta/info.json",
         field="meta/info.json is missing"),
    # ---------------------------------------------------------------- report: one bad rollout of several
    Case("report-one-npy-truncated",
         _session_cmd("report", "zs3", lambda s: truncate(s / F076 / "actions.npy"), "--json"), rc=0,
         check=_ok_report_rows(["f000", "f153"], "/f076", "f076/actions.npy", "not a readable .npy")),
    Case("report-one-npy-inf",
         _session_cmd("report", "zs3", _save(F076 + "/actions.npy", np.full((1, 24, 6), -np.inf)), "--json"), rc=0,
         check=_ok_report_rows(["f000", "f153"], "/f076", "f076/actions.npy", "non-finite value -inf")),
    Case("report-one-rollout-missing-kind",
         _session_cmd("report", "zs3", lambda s: drop_json_key(s / F076 / "rollout.json", "kind"), "--json"), rc=0,
         check=_ok_report_rows(["f000", "f153"], "/f076", "f076/rollout.json", "missing field 'kind'")),
    Case("report-one-bad-table-output",
         _session_cmd("report", "zs3", lambda s: (s / F076 / "actions.npy").write_bytes(b"")), rc=0,
         check=_check_table_lists_error),
    Case("report-one-npy-big-endian-float16-is-fine",
         _session_cmd("report", "zs3", lambda s: np.save(s / F076 / "actions.npy",
                                                         np.load(s / F076 / "actions.npy").astype(">f2")), "--json"),
         rc=0, check=_rows(["f000", "f076", "f153"])),
    Case("report-one-single-chunk-with-two-chunks",
         _session_cmd("report", "zs3", lambda s: np.save(s / F076 / "actions.npy", np.zeros((2, 24, 6))), "--json"),
         rc=0, check=_ok_report_rows(["f000", "f153"], "/f076", "f076/actions.npy", "expected 1 chunk, found 2")),
    Case("report-one-video-corrupt",
         _session_cmd("report", "zs3", lambda s: corrupt_middle(s / F076 / "video" / "front.mp4"), "--json"), rc=0,
         check=_ok_report_rows(["f000", "f153"], "/f076", "f076/video/front.mp4", "cannot decode video")),
    Case("report-one-gt-video-truncated",
         _session_cmd("report", "zs3", lambda s: truncate(s / F076 / "gt" / "video" / "gripper.mp4"), "--json"), rc=0,
         check=_ok_report_rows(["f000", "f153"], "/f076", "f076/gt/video/gripper.mp4", "cannot")),
    Case("report-absurd-1e30-still-reports", _session_cmd("report", "zs1", lambda s: _scale_actions(s, 1e30), "--json"),
         rc=0, check=_check_absurd_1e30),
    # a session named twice is one session: its rollouts are reported once
    Case("report-same-session-twice", _same_session_twice, rc=0, check=_rows(["f076"])),
    # ---------------------------------------------------------------- report: GT from a dataset
    # an episode the dataset lacks: the rollout is still reported (no GT), and a warning says why
    Case("report-dataset-episode-beyond",
         _ds_cmd("report", lambda ws, d, s: edit_json(s / "rollouts/r1/rollout.json", episode_index=7), "--json"), rc=0,
         check=_warned_rows(["r0", "r1"], "r1: dataset so101_v30 has no episode 7")),
    Case("report-dataset-start-frame-beyond",
         _ds_cmd("report", lambda ws, d, s: edit_json(s / "rollouts/r0/rollout.json", start_frame=500), "--json"), rc=0,
         check=_ok_report_rows(["r1"], "/r0", "r0/rollout.json", "start_frame 500 lies beyond episode 0 (150 frames)")),
    Case("report-dataset-gone-means-no-gt",
         _ds_cmd("report", lambda ws, d, s: edit_json(s / "session.json", gt_source={"dataset": str(d / "gone")}),
                 "--json"), rc=0, check=_check_no_dataset_gt),
    Case("report-dataset-data-parquet-truncated", _ds_with_broken_dataset(lambda ds: truncate(ds / V30_DATA)),
         file=V30_DATA, field="cannot read parquet"),
    # episode 0 is broken: its rollout is listed with the error, the one on episode 1 still reports
    Case("report-dataset-action-nan", _ds_with_broken_dataset(lambda ds: set_parquet_column(ds / V30_DATA, "action", nan_row)),
         rc=0, check=_ok_report_rows(["r1"], "/r0", V30_DATA, "action: non-finite value nan in episode 0 at frame_index 5")),
    Case("report-dataset-action-five-joints",
         _ds_with_broken_dataset(lambda ds: set_parquet_column(ds / V30_DATA, "action",
                                                               lambda rows: [r[:5] for r in rows], variable_list=True)),
         file=V30_DATA, field="action: expected 6 values per row, found 5"),
    # the first frames of episode 1 (what r1's 18 imagined frames pair with; 22% into the file) are
    # corrupt; frames no rollout uses are never decoded, so corruption there breaks nothing
    Case("report-dataset-video-corrupt", _ds_with_broken_dataset(lambda ds: corrupt_middle(ds / V30_FRONT, 4000, 0.22)),
         rc=0, check=_ok_report_rows(["r0"], "/r1", V30_FRONT, "cannot decode video")),
    Case("report-dataset-video-corrupt-where-unused", _ds_with_broken_dataset(
        lambda ds: corrupt_middle(ds / V30_FRONT, 4000, 0.5)), rc=0, check=_rows(["r0", "r1"])),
    Case("report-rollout-longer-than-episode", _long_rollouts, rc=0, check=_check_long),
    # ---------------------------------------------------------------- export
    Case("export-session-invalid-json", _export_cmd("zs1", lambda s: (s / "session.json").write_text("[")),
         file="session.json", field="invalid JSON"),
    Case("export-only-rollout-npy-nan", _export_cmd("zs1", _save(F076 + "/actions.npy", np.full((1, 24, 6), np.nan))),
         file="f076/actions.npy", field="non-finite"),
    Case("export-video-corrupt", _export_cmd("zs1", lambda s: corrupt_middle(s / F076 / "video" / "front.mp4"),
                                             "--rollout", "f076"),
         file="f076/video/front.mp4", field="cannot decode video"),
    Case("export-empty-session", _export_cmd("zs3", lambda s: _mk_empty(s / "rollouts")),
         file="zs3", field="no rollouts to export"),
    Case("export-empty-gt-actions", _export_cmd("zs1", _save(F076 + "/gt/actions.npy", np.zeros((0, 6))),
                                                "--rollout", "f076"),
         file="f076/gt/actions.npy", field="no GT steps"),
    Case("export-absurd-1e300", _export_cmd("zs1", lambda s: _scale_actions(s, 1e300)),
         file="f076/actions.npy", field="absurd value"),
    Case("export-one-bad-of-three", _export_cmd("zs3", lambda s: (s / F076 / "rollout.json").write_text("{"), out=""),
         file="f076/rollout.json", field="invalid JSON", out=("f000.rrd", "f153.rrd")),
]


# ==============================================================================================
# Running them


@pytest.fixture(scope="module")
def ws(dz_layout: Path, lerobot_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    return Workspace(tmp_path_factory.mktemp("malformed"), dz_layout, lerobot_dir)


def _run_case(case: Case, ws: Workspace, commands: queue.Queue[CommandServer]) -> Run:
    d = ws.root / "cases" / case.id
    (d / "out").mkdir(parents=True)
    (d / "tmp").mkdir()
    try:
        argv = [str(a) for a in case.build(ws, d)]
    except Exception as exc:  # a broken case, not a finding: report it on its own test
        return Run(case, d, -1, "", f"case setup failed: {type(exc).__name__}: {exc}")
    if argv[0] in ("report", "export") and "--jobs" not in argv and case.id not in IN_WORKERS:
        argv += ["--jobs", "1"]
    env = {**os.environ, "TMPDIR": str(d / "tmp")}
    server = commands.get()
    try:
        proc = server.run(*argv, timeout=300, env=env, cwd=d)
    finally:
        commands.put(server)
    return Run(case, d, proc.returncode, proc.stdout, proc.stderr)


@pytest.fixture(scope="module")
def runs(ws: Workspace) -> dict[str, Run]:
    """Every CLI case, run side by side, each in a process of its own forked from one of a few that
    imported the CLI once (``cli_processes``)."""
    servers = [CommandServer() for _ in range(SIDE_BY_SIDE)]
    commands: queue.Queue[CommandServer] = queue.Queue()
    for server in servers:
        commands.put(server)
    try:
        with ThreadPoolExecutor(max_workers=SIDE_BY_SIDE) as pool:
            return dict(zip([c.id for c in CASES], pool.map(lambda c: _run_case(c, ws, commands), CASES)))
    finally:
        for server in servers:
            server.close()


def test_cases_are_many_and_distinct():
    ids = [c.id for c in CASES]
    assert len(ids) == len(set(ids)) and len(ids) >= 40


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_cli_malformed(case: Case, runs: dict[str, Run]) -> None:
    run = runs[case.id]
    assert run.rc != -1, run.stderr
    assert "Traceback" not in run.stdout + run.stderr, run.stderr
    assert run.rc == case.rc, f"exit {run.rc}, expected {case.rc}; stderr: {run.stderr!r}"
    if case.rc == 2:
        lines = run.stderr.splitlines()
        assert len(lines) == 1 and run.stderr.endswith("\n"), run.stderr
        prefix, file, what = (lines[0].split(": ", 2) + ["", ""])[:3]
        assert prefix == "error", lines[0]
        assert case.file is not None and case.file in file, f"{case.file!r} not in file part of {lines[0]!r}"
        assert case.field is not None and case.field in what, f"{case.field!r} not in {lines[0]!r}"
    else:
        assert run.stderr == "", run.stderr  # no warnings either
    # nothing half-written: the output directory holds exactly what succeeded
    assert sorted(p.name for p in (run.dir / "out").iterdir()) == sorted(case.out)
    for rrd in (run.dir / "out").glob("*.rrd"):
        assert rrd.stat().st_size > 0
    assert list((run.dir / "tmp").iterdir()) == [], "temporary files left behind"
    if case.check is not None:
        case.check(run)


# ==============================================================================================
# The writer API (what evaluation scripts call): duplicate tags, bad arrays, nothing half-written


@pytest.mark.parametrize("second, message", [
    (dict(actions=np.zeros((2, 24, 6))), "rollout 'a' already exists"),  # a duplicate tag
    (dict(actions=np.zeros((2, 24, 5))), "shape: expected (n_chunks, 24, 6), found (2, 24, 5)"),
    (dict(actions=np.full((2, 24, 6), 1e200)), "absurd value 1e+200"),
    (dict(actions=np.zeros((2, 24, 6)), gt_actions=np.zeros((0, 6))), "no GT steps"),
    (dict(actions=np.zeros((2, 24, 6)), episode_index=-1), "episode_index: must be >= 0"),
], ids=["duplicate-tag", "joint-count", "absurd", "empty-gt", "negative-episode"])
def test_writer_refuses_and_leaves_nothing(tmp_path: Path, second: dict[str, Any], message: str) -> None:
    dest = tmp_path / "s"
    with pytest.raises(InspectorError) as err:
        with SessionWriter.create(dest) as w:
            w.add_rollout("a", kind="autoregressive", actions=np.zeros((2, 24, 6)))
            w.add_rollout("b" if "already" not in message else "a", kind="autoregressive", **second)
    assert message in str(err.value) and "\n" not in str(err.value)
    assert ".partial" not in err.value.file  # named where it would have been, not in a temp dir
    assert list(tmp_path.iterdir()) == []


# ==============================================================================================
# The app: a broken rollout is an error entry; Catalog.load raises only InspectorError


def test_app_catalog_broken_rollouts_are_errors(ws: Workspace, tmp_path: Path) -> None:
    catalog_module = pytest.importorskip("inspector.app._catalog")
    from inspector.app._frames import READY
    from inspector.app._robot import joint_child_links
    from inspector.data.sources import open_sources

    zs3 = ws.session(tmp_path / "a", "zs3")
    np.save(zs3 / F076 / "actions.npy", np.full((1, 24, 6), np.nan))  # fails on open
    edit_json(zs3 / "rollouts/f153/rollout.json", views=["front", "front"])  # fails on open
    ds = ws.ds_session(tmp_path / "b")
    edit_json(ds / "rollouts/r0/rollout.json", start_frame=500)  # fails when its timeline is built
    edit_json(ds / "rollouts/r1/rollout.json", episode_index=9)  # likewise
    zs1 = ws.session(tmp_path / "c", "zs1")
    corrupt_middle(zs1 / F076 / "video" / "front.mp4")  # loads; its view shows an error
    empty = ws.session(tmp_path / "d", "zs3")
    _mk_empty(empty / "rollouts")
    edit_json(empty / "session.json", name="empty")

    sources = open_sources([zs3, ds, zs1, empty])
    try:
        with ThreadPoolExecutor(2) as pool:
            catalog = catalog_module.Catalog(sources, pool, joint_child_links())
            assert sorted(catalog.keys()) == ["ds / r0", "ds / r1", "zs1 / f076", "zs3 / f000",
                                              "zs3 / f076", "zs3 / f153"]
            failed: dict[str, str] = {}
            for key in catalog.entries:
                try:
                    catalog.load(key)
                except InspectorError as exc:  # anything else would escape and fail the test
                    failed[key] = str(exc)
            assert sorted(failed) == ["ds / r0", "zs3 / f076", "zs3 / f153"]
            assert "f076/actions.npy" in failed["zs3 / f076"] and "non-finite" in failed["zs3 / f076"]
            assert "views: listed twice" in failed["zs3 / f153"]
            assert "start_frame 500" in failed["ds / r0"]
            no_episode = catalog.load("ds / r1").timeline
            assert not no_episode.has_gt_joints and "no episode 9" in no_episode.gt.warning
            assert all("\n" not in m for m in failed.values())
            # a failed build is retried on the next open, and fails the same clean way
            with pytest.raises(InspectorError):
                catalog.load("ds / r0")
            # the corrupt video fails alone: the rollout opens, that view carries the error
            loaded = catalog.load("zs1 / f076")
            assert loaded.frames.decoded.wait(60)  # every view settled: shown, or its error
            assert "front.mp4" in loaded.frames.status["front"] and "\n" not in loaded.frames.status["front"]
            assert loaded.frames.status["gripper"] == READY
            assert catalog.load("zs3 / f000").timeline.has_gt_joints
    finally:
        sources.close()
