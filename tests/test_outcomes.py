"""Outcome records: the store beside annotations.json (locked, atomic, never overwriting a bad
file), precedence between sources, outcome files (JSON lines, CSV) and what they refuse."""

from __future__ import annotations

import json
import multiprocessing
from pathlib import Path

import pytest

from inspector.errors import InspectorError
from inspector.outcomes import FAILURE_TAGS, effective_outcome, make_record, read_outcome_file, read_outcomes, sidecar_path, store_records, update_outcome


def test_labels_are_merged_field_by_field_and_cleared(tmp_path: Path) -> None:
    path = tmp_path / "outcomes.json"
    update_outcome(path, "ep0", {"success": True})
    update_outcome(path, "ep0", {"progress": 70})
    rec = update_outcome(path, "ep0", {"failure": "dropped", "note": "slipped at the end"})
    assert rec is not None
    assert (rec["success"], rec["progress"], rec["failure"], rec["source"]) == (True, 70.0, "dropped", "label")
    assert read_outcomes(path)["rollouts"]["ep0"]["label"] == rec
    assert update_outcome(path, "ep0", {"success": None, "progress": None, "failure": None, "note": ""}) is None
    assert read_outcomes(path)["rollouts"] == {}


def test_a_file_changed_after_it_was_read_is_validated_again(tmp_path: Path) -> None:
    """The store skips validating bytes it already found valid; bytes another process wrote are
    checked again (a progress of 250 is refused, not served from what was read before)."""
    path = tmp_path / "outcomes.json"
    update_outcome(path, "ep0", {"success": True, "progress": 40})
    first = read_outcomes(path)
    assert json.loads(path.read_text()) == first  # one rollout a line is still plain JSON
    assert len(path.read_text().splitlines()) == 7
    path.write_text(path.read_text().replace("40.0", "250.0"))
    with pytest.raises(InspectorError, match=r"rollouts\.ep0\.label\.progress"):
        read_outcomes(path)
    with pytest.raises(InspectorError, match="progress"):
        update_outcome(path, "ep0", {"success": False})
    assert "250.0" in path.read_text()  # never overwritten


@pytest.mark.parametrize(("changes", "field"), [({"success": "yes"}, "success"), ({"progress": 250}, "progress"),
                                                 ({"failure": "exploded"}, "failure"), ({"sucess": True}, "sucess")])
def test_bad_label_fields_are_refused_and_nothing_changes(tmp_path: Path, changes: dict, field: str) -> None:
    path = tmp_path / "outcomes.json"
    update_outcome(path, "ep0", {"success": True})
    before = path.read_bytes()
    with pytest.raises(ValueError, match=field):
        update_outcome(path, "ep0", changes)
    assert path.read_bytes() == before


def test_a_broken_file_is_named_and_never_overwritten(tmp_path: Path) -> None:
    path = tmp_path / "outcomes.json"
    path.write_text(json.dumps({"schema": "inspector.outcomes/1", "rollouts": {"ep0": {"label": {
        **make_record("label"), "progress": 250.0}}}}))
    before = path.read_bytes()
    with pytest.raises(InspectorError, match=r"rollouts\.ep0\.label\.progress: expected 0\.\.100"):
        read_outcomes(path)
    with pytest.raises(InspectorError, match="not overwriting"):
        update_outcome(path, "ep1", {"success": True})
    assert path.read_bytes() == before


def _label_many(path: str, worker: int) -> None:
    for i in range(15):
        update_outcome(path, f"w{worker}_{i}", {"success": i % 2 == 0, "progress": float(i)})


def test_concurrent_writers_lose_nothing(tmp_path: Path) -> None:
    """Four processes (as four tabs' servers would) label at once: every label survives."""
    path = tmp_path / "outcomes.json"
    ctx = multiprocessing.get_context("spawn")
    procs = [ctx.Process(target=_label_many, args=(str(path), w)) for w in range(4)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
        assert p.exitcode == 0
    rollouts = read_outcomes(path)["rollouts"]
    assert len(rollouts) == 60
    assert rollouts["w3_14"]["label"]["progress"] == 14.0
    assert not list(tmp_path.glob(".outcomes.json.*.tmp"))


def test_precedence_and_override() -> None:
    label = make_record("label", success=False)
    note_only = make_record("label", note="look again")
    file = make_record("file", success=True, progress=80.0)
    sim = make_record("sim", success=True)
    assert effective_outcome({"label": label, "file": file, "sim": sim}) is label
    assert effective_outcome({"label": note_only, "file": file, "sim": sim}) is file  # a note decides nothing
    assert effective_outcome({"sim": sim, "recording": make_record("recording", success=False)}) is sim
    assert effective_outcome({"label": label, "sim": sim}, prefer="sim") is sim
    assert effective_outcome({"label": label}, prefer="file") is None
    assert effective_outcome({}) is None


def test_outcome_files_json_lines_and_csv(tmp_path: Path) -> None:
    jl = tmp_path / "judge.jsonl"
    jl.write_text('{"tag": "ep0", "success": true, "progress": 100}\n\n'
                  '{"episode": 3, "start_frame": 0, "success": false, "failure": "missed_grasp", "note": "x"}\n')
    rows = read_outcome_file(jl)
    assert [(r.line, r.tag, r.episode, r.start_frame) for r in rows] == [(1, "ep0", None, None), (3, None, 3, 0)]
    assert rows[1].fields == {"success": False, "failure": "missed_grasp", "note": "x"}
    sheet = tmp_path / "sheet.csv"
    sheet.write_text("episode,success,progress,failure,note\n2,yes,40,,\n5,0,,timeout,ran out\n")
    rows = read_outcome_file(sheet)
    assert rows[0].fields == {"success": True, "progress": 40.0, "failure": None, "note": ""}
    assert rows[1].fields == {"success": False, "progress": None, "failure": "timeout", "note": "ran out"}


@pytest.mark.parametrize(("text", "message"), [
    ('{"tag": "a", "success": "maybe"}\n', "line 1: success: expected true, false or null"),
    ('{"tag": "a"}\n{"tag": "b", "progress": 250}\n', "line 2: progress: expected 0..100"),
    ('{"tag": "a", "failure": "exploded"}\n', "line 1: failure: unknown tag 'exploded'"),
    ('{"success": true}\n', "line 1: no 'tag' or 'episode'"),
    ("tag,success\na,perhaps\n", "line 2: success: expected true/false"),
    ('{"tag": "a", "progress": NaN}\n', "line 1: progress: non-finite number nan"),
])
def test_bad_outcome_files_name_the_line_and_field(tmp_path: Path, text: str, message: str) -> None:
    f = tmp_path / "bad.jsonl"
    f.write_text(text)
    with pytest.raises(InspectorError, match=message.replace("(", r"\(").replace(".", r"\.")) as exc:
        read_outcome_file(f)
    assert exc.value.file == str(f)


def test_session_failure_tags_extend_the_taxonomy(tmp_path: Path) -> None:
    path = tmp_path / "outcomes.json"
    with pytest.raises(ValueError, match="unknown tag"):
        store_records(path, {"ep0": {"failure": "knocked_over"}}, source="file", set_by="judge.jsonl")
    store_records(path, {"ep0": {"failure": "knocked_over"}}, source="file", set_by="judge.jsonl",
                  add_tags=["knocked_over"])
    doc = read_outcomes(path)
    assert doc["failure_tags"] == ["knocked_over"] and "knocked_over" not in FAILURE_TAGS
    assert doc["rollouts"]["ep0"]["file"]["set_by"] == "judge.jsonl"
    update_outcome(path, "ep1", {"failure": "knocked_over"})  # the app may use it now


def test_sidecar_sits_beside_the_raw_directory(tmp_path: Path) -> None:
    raw = tmp_path / "eval_run"
    raw.mkdir()
    assert sidecar_path(raw) == tmp_path / "eval_run.inspector-outcomes.json"
