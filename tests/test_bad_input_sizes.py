"""Files whose numbers do not fit and files sized to exhaust memory: one short line, exit 2 (or the
one bad item listed), and the whole CLI process well under 1.5 GB whatever the file claims.

Every hostile input is built here (tmp_path) and given to the real CLI in a subprocess; the
command's peak RSS and CPU time are read from ``getrusage(RUSAGE_CHILDREN)`` in a small wrapper
process, so nothing polls or sleeps.
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from eval_outputs import write_eval
from groot_dreams_layout import write_groot_dreams
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from offline_runs import write_run

from inspector.data.importers.groot_dreams import NeuralTrajectories
from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset
from inspector.errors import MAX_FILE_CHARS, MAX_WHAT_CHARS, InspectorError
from inspector.schema import MAX_WHOLE, whole_number

pytestmark = pytest.mark.slow  # the CLI as processes on large inputs, peak memory measured

# Generous bounds: these commands take 50-250 MiB after the fix, and 0.7-2.6 GB before it.
PEAK_RSS_MIB = 600
# The longest error line: the file (cut to about MAX_FILE_CHARS) and the message (MAX_WHAT_CHARS).
LONGEST_LINE = MAX_FILE_CHARS + MAX_WHAT_CHARS + 100

_WRAPPER = """
import resource, subprocess, sys
out, err, *argv = sys.argv[1:]
with open(out, "w") as o, open(err, "w") as e:
    rc = subprocess.call(argv, stdout=o, stderr=e)
u = resource.getrusage(resource.RUSAGE_CHILDREN)
print(rc, u.ru_maxrss, u.ru_utime + u.ru_stime)
"""


@dataclass
class Run:
    returncode: int
    stdout: str
    stderr: str
    peak_mib: float
    cpu_s: float


def cli(tmp_path: Path, *argv: object) -> Run:
    """``inspector ARGV...`` in a subprocess: its exit code, output, peak RSS and CPU time."""
    out, err = tmp_path / "cli.out", tmp_path / "cli.err"
    done = subprocess.run([sys.executable, "-c", _WRAPPER, str(out), str(err), sys.executable, "-m", "inspector",
                           *map(str, argv)], capture_output=True, text=True, timeout=900, check=True)
    rc, maxrss_kib, cpu = done.stdout.split()
    return Run(int(rc), out.read_text(errors="replace"), err.read_text(errors="replace"),
               int(maxrss_kib) / 1024, float(cpu))


def assert_one_error_line(run: Run, *needles: str) -> None:
    assert run.returncode == 2, (run.returncode, run.stderr[-2000:])
    assert run.stderr.count("\n") == 1 and run.stderr.startswith("error: "), run.stderr[:2000]
    assert "Traceback" not in run.stderr and len(run.stderr) < LONGEST_LINE, run.stderr[:2000]
    for needle in needles:
        assert needle in run.stderr, run.stderr


# ----------------------------------------------------------------------------------------------
# Numbers that do not fit


def _groot(tmp_path: Path) -> Path:
    return write_groot_dreams(tmp_path / "dump", [("pick the cube", 12)])


def _edit(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize("command", ["info", "report", "import"])
def test_an_index_past_any_integer_type_in_modality_json_is_one_line(tmp_path, command):
    root = _groot(tmp_path)
    _edit(root / "meta/modality.json",
          lambda m: m["action"].update(main_gripper={"start": 2**70, "end": 2**70 + 1, "absolute": False}))
    argv = {"info": ["info", root], "report": ["report", "--no-cache", "--jobs", "1", root],
            "import": ["import", "groot-dreams", root, "-o", tmp_path / "s"]}[command]
    run = cli(tmp_path, *argv)
    assert_one_error_line(run, "meta/modality.json", "action.main_gripper.start")
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("field,value,needle", [
    ("sum_rewards", 10**400, "per_task[0].metrics.sum_rewards[0]: expected a finite number"),
    ("task_id", 2**70, "per_task[0].task_id"),
], ids=["reward-10e400", "task_id-2e70"])
def test_eval_info_numbers_past_float_and_int64_are_the_tasks_error(tmp_path, field, value, needle):
    root = tmp_path / "out"
    write_eval(root, {("so101_sim", 0): [True], ("so101_sim", 1): [False]}, steps=8)
    text = (root / "eval_info.json").read_text()
    data = json.loads(text)
    if field == "task_id":
        data["per_task"][0]["task_id"] = value
    else:
        data["per_task"][0]["metrics"][field][0] = value
    (root / "eval_info.json").write_text(json.dumps(data))
    run = cli(tmp_path, "info", "--json", root)
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr[-2000:]
    errors = json.loads(run.stdout)["errors"]
    assert any(needle in e and "eval_info.json" in e for e in errors.values()), errors
    imported = cli(tmp_path, "import", "lerobot-eval", root, "-o", tmp_path / "s")
    assert_one_error_line(imported, "eval_info.json", needle)
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("file,change,needle", [
    ("metadata.json", lambda m: m.update(actions_per_chunk=2**70), "actions_per_chunk"),
    ("metadata.json", lambda m: m["input_joint_positions"].update(gripper=10**400),
     "input_joint_positions.gripper: expected a finite number"),
    ("inspector_gt.json", lambda m: m.update(fps=10**400), "fps:"),
    ("inspector_gt.json", lambda m: m.update(start_frame=2**70), "start_frame"),
], ids=["actions_per_chunk-2e70", "input_joint-10e400", "sidecar-fps-10e400", "sidecar-start_frame-2e70"])
def test_offline_run_numbers_that_do_not_fit_are_one_line(tmp_path, file, change, needle):
    run_dir = tmp_path / "run"
    write_run(run_dir, 1, pngs=False, sidecar=None)
    if not (run_dir / file).exists():
        (run_dir / file).write_text("{}")
    _edit(run_dir / file, change)
    run = cli(tmp_path, "import", "dreamzero-offline", run_dir, "-o", tmp_path / "s")
    assert_one_error_line(run, file, needle)
    assert not (tmp_path / "s").exists()


_ints = st.integers() | st.sampled_from([2**53, 2**63 - 1, 2**63, 2**64, 2**70, -(2**70), 10**400])


@pytest.fixture(scope="module")
def groot_root(tmp_path_factory) -> Path:
    return write_groot_dreams(tmp_path_factory.mktemp("groot") / "dump", [("pick the cube", 6)], video=False)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(where=st.sampled_from(["column", "end", "chunks_size", "episode_index", "length", "task_index"]),
       value=_ints)
def test_any_integer_in_a_groot_dump_reads_or_is_an_error_naming_it(groot_root, where, value):
    """Whatever integer a GR00T-Dreams dump's metadata holds, the dump reads or one InspectorError
    names the file and the field; never an OverflowError."""
    meta = groot_root / "meta"
    saved = {f: (meta / f).read_text() for f in ("modality.json", "info.json", "episodes.jsonl", "tasks.jsonl")}
    try:
        if where == "column":  # a one-column slice at that column
            _edit(meta / "modality.json", lambda m: m["action"]["main_wrist_roll"].update(start=value, end=value + 1))
        elif where == "end":
            _edit(meta / "modality.json", lambda m: m["action"]["main_wrist_roll"].update(end=value))
        elif where == "chunks_size":
            _edit(meta / "info.json", lambda m: m.update(chunks_size=value))
        elif where == "task_index":
            row = json.loads(saved["tasks.jsonl"].splitlines()[0])
            (meta / "tasks.jsonl").write_text(json.dumps({**row, "task_index": value}) + "\n")
        else:
            row = json.loads(saved["episodes.jsonl"].splitlines()[0])
            (meta / "episodes.jsonl").write_text(json.dumps({**row, where: value}) + "\n")
        try:
            ds = NeuralTrajectories(groot_root)
            for e in ds.episodes:
                ds.trajectory(e.index)
        except InspectorError as exc:
            assert exc.file and exc.what and "\n" not in str(exc) and len(str(exc)) < LONGEST_LINE
    finally:
        for f, text in saved.items():
            (meta / f).write_text(text)


@given(value=_ints | st.floats() | st.booleans() | st.text(max_size=3) | st.none(),
       minimum=st.integers(-5, 5))
def test_whole_number_returns_the_value_in_bounds_or_names_the_field(value, minimum):
    try:
        got = whole_number(value, "f.json", "a.b", minimum=minimum)
    except InspectorError as exc:
        assert str(exc).startswith("f.json: a.b: ") and len(str(exc)) < 200
        assert isinstance(value, bool) or not isinstance(value, int) or not minimum <= value <= MAX_WHOLE
    else:
        assert got == value and type(value) is int and minimum <= got <= MAX_WHOLE


# ----------------------------------------------------------------------------------------------
# Memory on hostile sizes


def test_an_eval_info_of_a_million_episodes_lists_what_the_directory_holds(tmp_path):
    """1,000,000 episodes listed, 2 recorded: the 2, the first 100 of the others each as an error,
    the rest one error counting them; in seconds and a few hundred MB."""
    root = tmp_path / "out"
    write_eval(root, {("so101_sim", 0): [True, False]}, steps=8)
    n = 1_000_000
    _edit(root / "eval_info.json", lambda i: i["per_task"][0]["metrics"].update(
        successes=[True] * n, sum_rewards=[1.0] * n, max_rewards=[1.0] * n))
    run = cli(tmp_path, "info", "--json", root)
    assert run.returncode == 0, run.stderr[-2000:]
    info = json.loads(run.stdout)
    assert info["tasks"] == [{"task": "so101_sim_0", "episodes": n, "successes": n, "recorded": 2,
                              "success_rate": 1.0}]
    assert len(info["episodes"]) == 2 + 100 and info["episodes"][0]["length"] == 8
    rest = info["errors"]["so101_sim_0_ep102_and_later"]
    assert "999,898 more episodes from episode 102 on" in rest and "lists 1,000,000" in rest
    assert run.peak_mib < PEAK_RSS_MIB and run.cpu_s < 30, (run.peak_mib, run.cpu_s)
    text = cli(tmp_path, "info", root)
    assert text.returncode == 0 and len(text.stdout.splitlines()) < 200, len(text.stdout.splitlines())


def test_a_csv_of_millions_of_rows_beside_a_short_video_is_refused_after_the_rows_it_can_hold(tmp_path):
    """25 frames make at most 3 chunks of 24 actions: row 73 is refused, the other 3 million unread."""
    run_dir = tmp_path / "run"
    write_run(run_dir, 3, pngs=False)
    row = ",1.0,2.0,3.0,4.0,5.0,6.0\n"
    with (run_dir / "predicted_actions.csv").open("w") as f:
        f.write("step,shoulder_pan,shoulder_lift,elbow_flex,wrist_flex,wrist_roll,gripper\n")
        f.writelines(f"{i}{row}" for i in range(3_000_000))
    run = cli(tmp_path, "import", "dreamzero-offline", run_dir, "-o", tmp_path / "s")
    assert_one_error_line(run, "predicted_actions.csv", "line 74: more than 72 rows",
                          "25 frames make at most 3 chunk(s)")
    assert run.peak_mib < PEAK_RSS_MIB and run.cpu_s < 30, (run.peak_mib, run.cpu_s)
    assert not (tmp_path / "s").exists()


def test_a_csv_line_of_a_million_fields_is_refused_before_it_is_held(tmp_path):
    run_dir = tmp_path / "run"
    write_run(run_dir, 1, pngs=False)
    with (run_dir / "predicted_actions.csv").open("a") as f:
        f.write(",".join(["1"] * 5_000_000) + "\n")
    run = cli(tmp_path, "import", "dreamzero-offline", run_dir, "-o", tmp_path / "s")
    assert_one_error_line(run, "predicted_actions.csv", "a line longer than")
    assert run.peak_mib < PEAK_RSS_MIB, run.peak_mib


def _dataset(tmp_path: Path) -> Path:
    s = np.zeros((4, 6))
    return write_lerobot_dataset(tmp_path / "ds", [EpisodeData("a", s, s, {"front": np.zeros((4, 16, 16, 3), np.uint8)})])


@pytest.mark.parametrize("key,template,needle", [
    ("data_path", "data/chunk-{chunk_index:03d}/file-{file_index:>300000000}.parquet",
     "field 'file_index' asks for a width of 300000000 (at most 32)"),
    ("video_path", "videos/{video_key:>200000000}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4",
     "field 'video_key' asks for a width of 200000000"),
    ("data_path", "data/{chunk_index.real}/{file_index}.parquet", "unknown field 'chunk_index.real'"),
    ("data_path", "data/{episode_index}.parquet", "unknown field 'episode_index'"),
    ("video_path", "videos/{video_key:{file_index}}.mp4", "has an unsupported format"),
])
@pytest.mark.parametrize("command", ["info", "report"])
def test_a_path_template_is_checked_when_info_json_is_read(tmp_path, key, template, needle, command):
    root = _dataset(tmp_path)
    _edit(root / "meta/info.json", lambda i: i.update({key: template}))
    run = cli(tmp_path, *(["info", root] if command == "info" else ["report", "--no-cache", "--jobs", "1", root]))
    assert_one_error_line(run, "meta/info.json", f"'{key}'", needle)
    assert run.peak_mib < PEAK_RSS_MIB, run.peak_mib


def test_an_error_quoting_ten_megabytes_is_one_readable_line(tmp_path):
    """The message quotes the value; the line keeps the file, the field and the start of it."""
    root = _dataset(tmp_path)
    _edit(root / "meta/info.json", lambda i: i.update(fps="x" * 10_000_000))
    run = cli(tmp_path, "info", root)
    assert_one_error_line(run, "meta/info.json: 'fps' must be a number of frames per second, found 'xxx")
    assert run.peak_mib < PEAK_RSS_MIB, run.peak_mib


def test_a_long_path_keeps_its_start_and_its_file_name():
    path = "/data/" + "deep/" * 400 + "meta/info.json"
    what = "fps: expected a number, found 'x'" + "y" * 10_000
    line = str(InspectorError(path, what))
    assert line.startswith("/data/deep/") and "/deep/meta/info.json: fps: expected a number" in line
    assert line.count("...") == 2 and f"({len(what):,} characters in all)" in line and len(line) < LONGEST_LINE


@pytest.mark.parametrize("layout", ["dataset", "eval"])
def test_a_metadata_file_of_empty_lists_past_32_mb_is_refused_unparsed(tmp_path, layout):
    """12 million empty lists take a GB as objects: the file's size is checked before it is parsed."""
    if layout == "dataset":
        root, file = _dataset(tmp_path), "meta/info.json"
    else:
        root, file = tmp_path / "out", "eval_info.json"
        write_eval(root, {("so101_sim", 0): [True]}, steps=8)
    text = (root / file).read_text()
    (root / file).write_text(text.rstrip()[:-1] + ', "padding": [' + "[]," * 12_000_000 + "[]]}")
    run = cli(tmp_path, "info", root)
    assert_one_error_line(run, file, "bytes: larger than any metadata file (at most 33,554,432 bytes are read)")
    assert run.peak_mib < PEAK_RSS_MIB, run.peak_mib
