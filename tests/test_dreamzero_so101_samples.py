"""Every sample a DreamZero-SO101 checkout lists, the distribution each comes from, and the
repository's own figures beside inspector's.

The checkouts are copies of the layout made from the bundled demo (``dreamzero_layout.py``) with
an ``aggregate.json`` of the real schema written by ``write_aggregate`` (the real file is not
ours to ship): some samples have a folder, some only their entry.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from dreamzero_layout import TRAINING_DATASET, ZERO_SHOT_DATASET, write_aggregate

from inspector.data.importers.dreamzero_so101 import import_dreamzero
from inspector.data.session import open_session
from inspector.errors import InspectorError


@pytest.fixture
def checkout(dz_layout: Path, tmp_path: Path) -> Path:
    """``zeroshot_chunk/`` with folders f000 and f076 (f153's folder not shipped) and an
    aggregate.json listing f000, f076, f153 and two samples that never had a folder."""
    root = tmp_path / "dreamzero_so101"
    shutil.copytree(dz_layout / "zeroshot_chunk", root / "zeroshot_chunk")
    write_aggregate(root / "zeroshot_chunk")
    shutil.rmtree(root / "zeroshot_chunk" / "f153")
    return root


def _report(path: Path) -> dict:
    from inspector.report.build import build_report

    return build_report([str(path)], jobs=1, use_cache=False)


def test_every_listed_sample_is_a_rollout_those_without_a_folder_without_video(checkout, tmp_path):
    aggregate = json.loads((checkout / "zeroshot_chunk" / "aggregate.json").read_text())
    logged: list[str] = []
    s = open_session(import_dreamzero(checkout, tmp_path / "s", log=logged.append))
    assert not s.errors
    assert sorted(s.rollouts) == sorted(e["tag"] for e in aggregate["samples"]) == [
        "f000", "f076", "f153", "s005", "s082"]
    for entry in aggregate["samples"]:
        r = s.rollouts[entry["tag"]]
        np.testing.assert_array_equal(r.actions[0], entry["actions_pred"])
        np.testing.assert_array_equal(r.gt_actions, entry["actions_gt"])
        assert r.start_frame == entry["frame_in_ep"] and r.episode_index == 1 and r.gt_episode_length == 409
        assert r.prompt == aggregate["prompt"]  # the folders' metas have none: the aggregate's
        folder = (checkout / "zeroshot_chunk" / entry["tag"]).is_dir()
        assert bool(r.views) is folder
        notes = r.extra.get("source_notes", [])
        if folder:
            assert notes == []
        else:
            assert len(notes) == 1 and "shown without video" in notes[0]
            assert f"no sample folder dreamzero_so101/zeroshot_chunk/{entry['tag']}" in notes[0]
            assert "aggregate.json samples[" in notes[0]
            line = next(x for x in logged if x.startswith(entry["tag"] + ":"))
            assert "views none" in line and "warning: no sample folder" in line


@pytest.mark.slow
def test_the_zero_shot_mean_is_the_aggregates_whatever_folders_ship(checkout):
    """The mean over every sample equals the aggregate's own mean, and the report says which
    samples came without video."""
    aggregate = json.loads((checkout / "zeroshot_chunk" / "aggregate.json").read_text())
    report = _report(checkout)
    rows = {r["tag"]: r for r in report["rollouts"]}
    zero_shot = [r["rmse_deg"] for r in rows.values() if r["distribution"] == "zero-shot"]
    assert len(zero_shot) == aggregate["n_samples"] == 5
    assert np.mean(zero_shot) == pytest.approx(np.mean([e["action_rmse_deg"] for e in aggregate["samples"]]),
                                               abs=1e-9)
    assert np.mean(zero_shot) == pytest.approx(aggregate["mean_action_rmse_deg"], abs=1e-9)
    for e in aggregate["samples"]:
        assert rows[e["tag"]]["rmse_deg"] == pytest.approx(e["action_rmse_deg"], abs=1e-9)
    without = sorted(w.split(":")[0] for w in report["warnings"] if "shown without video" in w)
    assert without == ["f153", "s005", "s082"]
    figures = rows["s005"]["repository_figures"]
    assert "repository's own figures" in figures["label"]
    assert figures["figures"]["aggregate.json:mean_action_rmse_deg"] == aggregate["mean_action_rmse_deg"]
    assert figures["figures"]["action_rmse_deg"] == aggregate["samples"][3]["action_rmse_deg"]
    from inspector.report.build import format_report

    text = format_report(report)
    assert f"inspector's mean RMSE of the same 5 sample(s): {np.mean(zero_shot):.2f} deg" in text
    assert f"mean_action_rmse_deg {aggregate['mean_action_rmse_deg']:.2f}" in text
    assert "zero-shot: f000, f076, f153, s005, s082" in text
    json.dumps(report, allow_nan=False)  # strict JSON


def test_folder_and_aggregate_that_disagree_are_named_and_the_folder_is_used(checkout, tmp_path):
    path = checkout / "zeroshot_chunk" / "aggregate.json"
    data = json.loads(path.read_text())
    moved = (np.asarray(data["samples"][1]["actions_pred"]) + 2.5).tolist()
    data["samples"][1]["actions_pred"] = moved
    data["samples"][1]["frame_in_ep"] = 77
    path.write_text(json.dumps(data))
    s = open_session(import_dreamzero(checkout, tmp_path / "s", log=lambda _: None))
    folder = json.loads((checkout / "zeroshot_chunk" / "f076" / "meta.json").read_text())
    f076 = s.rollouts["f076"]
    np.testing.assert_array_equal(f076.actions[0], folder["actions_pred"])
    assert f076.start_frame == folder["frame_in_ep"] == 76
    [note] = f076.extra["source_notes"]
    assert note.startswith("dreamzero_so101/zeroshot_chunk/f076/meta.json and "
                           "dreamzero_so101/zeroshot_chunk/aggregate.json samples[1] differ in ")
    assert "actions_pred (max |diff| 2.5)" in note and "frame_in_ep (76 vs 77)" in note
    assert note.endswith("the folder's meta.json is used")
    assert "source_notes" not in s.rollouts["f000"].extra  # f000 agrees: nothing to say


def test_distribution_marks(checkout, dz_layout, tmp_path):
    """Zero-shot from the aggregate's disclosure (its dataset kept); training for the training
    rollouts and the held-out and train_ep demo samples (the dataset a disclosure names)."""
    shutil.copytree(dz_layout / "train_rollout", checkout / "train_rollout")
    demo = checkout / "demo"
    shutil.copytree(dz_layout / "demo", demo)
    entry = json.loads((demo / "train_ep0" / "meta.json").read_text())
    (demo / "all_metas.json").write_text(json.dumps([entry, {**entry, "tag": "heldout_ep50", "episode": 1}]))
    s = open_session(import_dreamzero(checkout, tmp_path / "s", log=lambda _: None))
    marks = {tag: (r.extra.get("distribution"), r.extra.get("dataset")) for tag, r in s.rollouts.items()}
    assert marks == {**{t: ("zero-shot", ZERO_SHOT_DATASET) for t in ("f000", "f076", "f153", "s005", "s082")},
                     **{t: ("training", TRAINING_DATASET) for t in ("ep000_train", "train_ep0", "heldout_ep50")}}
    assert "zero_shot_disclosure" in s.rollouts["f000"].extra["distribution_source"]
    assert "held-out episode" in s.rollouts["heldout_ep50"].extra["distribution_source"]
    assert s.rollouts["heldout_ep50"].views == [] and s.rollouts["train_ep0"].views  # the folder's, agreeing


def test_an_aggregate_without_a_disclosure_is_judged_by_its_dataset(tmp_path):
    from inspector.data.importers.dreamzero_so101_summaries import SampleIndex, distribution_of

    training = (TRAINING_DATASET, tmp_path / "zeroshot_chunk" / "aggregate.json")
    index = SampleIndex(tmp_path / "evals" / "aggregate.json", [], dataset=TRAINING_DATASET)
    assert distribution_of(tmp_path / "evals" / "f010", "f010", index, training, str)["distribution"] == "training"
    index.dataset = ZERO_SHOT_DATASET
    marked = distribution_of(tmp_path / "evals" / "f010", "f010", index, training, str)
    assert marked["distribution"] == "zero-shot" and marked["dataset"] == ZERO_SHOT_DATASET
    assert f"is not the training dataset {TRAINING_DATASET}" in marked["distribution_source"]
    # nothing says: no mark (never a guess)
    assert distribution_of(tmp_path / "evals" / "f010", "f010", None, None, str) == {}


def test_the_repositorys_drift_summaries_are_kept_beside_ours(tmp_path):
    """``train_rollout/`` summary files: each figure kept as ``<file>:<field>``, labelled in the
    report as the repository's, never in place of inspector's drift; a broken one is a note."""
    root = tmp_path / "dz" / "train_rollout"
    rollout = root / "ep000_train"
    rollout.mkdir(parents=True)
    np.save(rollout / "action_trace.npy", np.zeros((3, 24, 6)))
    (rollout / "meta.json").write_text(json.dumps({"episode": 0, "prompt": "Pick the red cube", "frames_per_step": 9,
                                                   "mean_drift_deg": 137.6, "final_drift_deg": 231.7}))
    (root / "honest_summary.json").write_text(json.dumps([{"tag": "ep000_train", "time_aligned_mean": 96.8,
                                                           "time_aligned_final": 165.4, "best_match_mean": 93.7}]))
    (root / "drift_recomputed.json").write_text(json.dumps({"ep000_train": {"drift_vs_state_clipped_mean": 96.8,
                                                                            "reached_within_tau": True}}))
    (root / "summary.json").write_text('{"rollouts": NaN}')
    s = open_session(import_dreamzero(tmp_path / "dz", tmp_path / "s", log=lambda _: None))
    extra = s.rollouts["ep000_train"].extra
    assert extra["reference_metrics"] == {
        "mean_drift_deg": 137.6, "final_drift_deg": 231.7, "honest_summary.json:time_aligned_mean": 96.8,
        "honest_summary.json:time_aligned_final": 165.4, "honest_summary.json:best_match_mean": 93.7,
        "drift_recomputed.json:drift_vs_state_clipped_mean": 96.8, "drift_recomputed.json:reached_within_tau": True}
    assert set(extra["reference_sources"]) == {"meta.json", "honest_summary.json", "drift_recomputed.json"}
    [note] = extra["source_notes"]
    assert note.startswith("the repository's dz/train_rollout/summary.json not read: rollouts: non-finite")
    assert extra["distribution"] == "training"

    from inspector.report.build import format_report

    report = _report(tmp_path / "dz")
    [row] = report["rollouts"]
    assert row["repository_figures"]["figures"]["honest_summary.json:time_aligned_mean"] == 96.8
    assert row["time_aligned_drift"] is None  # no GT joints: ours not measured, theirs not taken in its place
    text = format_report(report)
    assert "Source figures (the repository's own figures" in text
    assert "honest_summary.json: time_aligned_mean 96.80, time_aligned_final 165.40, best_match_mean 93.70" in text
    assert f"warning: ep000_train: {note}" in text


# -- hostile aggregate.json -------------------------------------------------------------------


def _edit(checkout: Path, change) -> Path:
    path = checkout / "zeroshot_chunk" / "aggregate.json"
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))
    return path


BAD_SAMPLES = [
    ("wrong-shape", lambda d: d["samples"][3].update(actions_pred=[[1, 2, 3]]),
     "samples[3]: actions_pred: expected shape (horizon, 6), found (1, 3)"),
    ("missing-actions", lambda d: d["samples"][3].pop("actions_pred"), "samples[3]: missing field 'actions_pred'"),
    ("not-an-object", lambda d: d["samples"].__setitem__(3, 5), "samples[3]: expected an object, found int"),
    ("bad-state", lambda d: d["samples"][3].update(state_in=[1, 2]), "samples[3]: state_in: expected shape (6,)"),
    ("gt-shape", lambda d: d["samples"][3].update(actions_gt=d["samples"][3]["actions_gt"][:5]),
     "samples[3]: actions_gt: shape (5, 6) differs from actions_pred (24, 6)"),
    ("absurd", lambda d: d["samples"][3]["actions_pred"][0].__setitem__(0, 1e300), "samples[3]: actions_pred: absurd"),
]


@pytest.mark.parametrize("name, change, what", BAD_SAMPLES, ids=[b[0] for b in BAD_SAMPLES])
def test_a_bad_sample_stops_the_import_with_one_line_naming_file_and_field(checkout, tmp_path, name, change, what):
    path = _edit(checkout, change)
    with pytest.raises(InspectorError) as exc:
        import_dreamzero(checkout, tmp_path / "s", log=lambda _: None)
    assert exc.value.file == str(path) and exc.value.what.startswith(what) and "\n" not in str(exc.value)
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("change, what", [
    (lambda d: d["samples"][2]["actions_pred"][0].__setitem__(0, float("nan")),
     "samples[2].actions_pred[0][0]: non-finite number nan"),
    (lambda d: d.update(samples={"f000": 1}), "samples: expected a list, found dict"),
    (lambda d: d.update(zero_shot_disclosure=5), "zero_shot_disclosure: expected a string, found 5"),
])
def test_a_bad_aggregate_is_one_line_naming_file_and_field(checkout, tmp_path, change, what):
    path = _edit(checkout, change)
    with pytest.raises(InspectorError) as exc:
        import_dreamzero(checkout, tmp_path / "s", log=lambda _: None)
    assert exc.value.file == str(path) and exc.value.what.startswith(what)


@pytest.mark.slow
def test_read_in_place_a_bad_sample_is_listed_under_errors_and_the_others_load(checkout):
    _edit(checkout, lambda d: d["samples"][3].update(actions_pred=[[1, 2, 3]]))
    report = _report(checkout)
    assert sorted(r["tag"] for r in report["rollouts"]) == ["f000", "f076", "f153", "s082"]
    [(key, err)] = report["errors"].items()
    assert key.endswith("/s005") and "aggregate.json: samples[3]: actions_pred: expected shape" in err
    (checkout / "zeroshot_chunk" / "aggregate.json").write_text("{not json")  # the whole file: the folders load
    report = _report(checkout)
    assert sorted(r["tag"] for r in report["rollouts"]) == ["f000", "f076"]
    assert "invalid JSON" in next(iter(report["errors"].values()))


def test_hostile_tags_never_reach_outside(checkout, tmp_path):
    _edit(checkout, lambda d: (d["samples"][3].update(tag="../../etc"), d["samples"][4].update(tag=7)))
    s = open_session(import_dreamzero(checkout, tmp_path / "s", log=lambda _: None))
    assert sorted(s.rollouts) == ["f000", "f076", "f153", "sample3", "sample4"]
    assert all(not r.views for t, r in s.rollouts.items() if t.startswith("sample"))


def test_info_names_the_samples_without_a_folder(checkout, tmp_path):
    """``inspector info`` on the checkout (read in place, nothing decoded) and on the session
    imported from it says which samples come without video."""
    from inspector.data.info import describe, format_info

    info = describe(checkout)
    assert info["format"] == "dreamzero-so101"
    by_tag = {r["tag"]: r for r in info["rollouts"]}
    assert sorted(by_tag) == ["f000", "f076", "f153", "s005", "s082"]
    assert by_tag["f000"]["views"] == ["front", "gripper"] and by_tag["f000"]["warnings"] == []
    assert by_tag["f153"]["views"] == [] and "shown without video" in by_tag["f153"]["warnings"][0]
    assert {r["distribution"] for r in info["rollouts"]} == {"zero-shot"}
    text = format_info(info)
    assert "f153" in text and "warning: no sample folder dreamzero_so101/zeroshot_chunk/f153" in text
    session = describe(import_dreamzero(checkout, tmp_path / "s", log=lambda _: None))
    warned = {r["tag"] for r in session["rollouts"] if r.get("warnings")}
    assert warned == {"f153", "s005", "s082"}
    assert "warning: no sample folder" in format_info(session)


def test_real_samples_with_an_aggregate_of_their_schema(dreamzero_dir, tmp_path):
    """The real model outputs' three sample folders, listed with two more in an aggregate.json
    of the repository's schema: every listed sample is read, each RMSE equals its entry's."""
    root = tmp_path / "dreamzero_so101"
    chunk = root / "zeroshot_chunk"
    for folder in sorted((dreamzero_dir / "zeroshot_chunk").iterdir()):
        (chunk / folder.name).mkdir(parents=True)
        shutil.copyfile(folder / "meta.json", chunk / folder.name / "meta.json")  # the actions; no video needed
    aggregate = write_aggregate(chunk, extra_samples=2)
    s = open_session(import_dreamzero(root, tmp_path / "s", log=lambda _: None))
    from inspector.analysis.timeline import build_timeline

    rmse = {tag: build_timeline(r).chunk_errors.rmse for tag, r in s.rollouts.items()}
    assert sorted(rmse) == sorted(e["tag"] for e in aggregate["samples"]) == ["f000", "f084", "f169", "s005", "s090"]
    for e in aggregate["samples"]:
        assert rmse[e["tag"]] == pytest.approx(e["action_rmse_deg"], abs=1e-9)
    assert np.mean(list(rmse.values())) == pytest.approx(aggregate["mean_action_rmse_deg"], abs=1e-9)
    assert {r.extra["distribution"] for r in s.rollouts.values()} == {"zero-shot"}
