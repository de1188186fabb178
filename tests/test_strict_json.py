"""Every ``--json`` output, on every layout the tests can build, is strict JSON (RFC 8259: no bare
``NaN`` or ``Infinity``, which Node, ``jq`` and most parsers reject), and so is every JSON file an
import or a vote writes. What cannot be measured is null: a video-only rollout (DreamZero's served
predictions, a lerobot-eval run without recordings) has no seams, and a view whose imagined frames
have another geometry than the GT's (a 2-camera mosaic beside one camera's render) has no PSNR, a
note saying why instead.
"""

from __future__ import annotations

import datetime
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_processes import module_command_server
from conftest import real_fixtures_dir, real_outputs_skip_reason
from demo_copies import DEMO, demo_copy
from eval_outputs import H, W, flat, predicted_level, render_level, write_eval
from groot_dreams_layout import write_groot_dreams
from offline_runs import write_run
from served_layout import save_client_episode, save_prediction, served_frames

from inspector.analysis.timeline import build_timeline
from inspector.analysis.video_metrics import compare_clips, geometry_note
from inspector.app._cards import headline_metrics
from inspector.data.importers.dreamzero_served import import_served
from inspector.data.importers.lerobot_eval import import_eval
from inspector.data.session import SessionWriter, open_session
from inspector.data.video import VideoClip, encode_h264
from inspector.outcomes import OUTCOMES_FILE, store_records
from inspector.said.votes import Side, new_vote, save_vote
from inspector.schema import NotJsonError, json_text

LEROBOT = Path(__file__).resolve().parent / "data" / "lerobot"
WHEN = datetime.datetime(2026, 3, 14, 15, 9, 26)
MOSAIC_VIEW = 64  # the mosaic's two square views [px], beside a W x H (4:3) render
CHECKPOINTS = ("ckpt-a", "ckpt-b", "ckpt-c")
TASKS = ("pick the cube", "open the drawer")

_command_server, _run_command = module_command_server()


def strict_json(text: str) -> Any:
    """``text`` parsed as strict JSON: a bare NaN, Infinity or -Infinity is an error."""
    def refuse(token: str) -> Any:
        raise ValueError(f"{token} is not JSON")
    return json.loads(text, parse_constant=refuse)


def cli(*argv: object) -> Any:
    """``inspector *argv`` (exit 0 expected): its standard output, parsed strictly."""
    run = _run_command(*argv, timeout=300)
    assert run.returncode == 0, f"inspector {' '.join(map(str, argv))}: {run.stderr[-2000:]}"
    return strict_json(run.stdout)


def write_decision_session(dest: Path, checkpoint: str, successes: dict[str, int], n: int = 4) -> Path:
    """A session of ``checkpoint``: per task ``n`` rollouts, the first ``successes[task]`` judged a
    success in its outcomes file."""
    records = {}
    with SessionWriter.create(dest, name=dest.name, model={"name": checkpoint}) as writer:
        for t, task in enumerate(successes):
            for i in range(n):
                tag = f"t{t}_r{i:02d}"
                writer.add_rollout(tag, kind="single_chunk", actions=np.zeros((1, 4, 6)), prompt=task,
                                   executed_per_chunk=4, episode_index=t, start_frame=i)
                records[tag] = {"success": i < successes[task], "progress": 100.0 if i < successes[task] else 30.0}
    store_records(dest / OUTCOMES_FILE, records, source="file", set_by="judge.jsonl")
    return dest


def write_mosaic_eval(root: Path) -> Path:
    """A lerobot-eval run without recordings whose predicted video is a mosaic of two square views
    (2 x 64 = 128x64) beside a 128x96 render: the heights differ, so it is not split, and its one
    imagined view has another geometry than the render it is paired with."""
    write_eval(root, {("so101_sim", 0): [True, False]}, record=False)
    for pred in sorted((root / "videos" / "so101_sim_0").glob("pred_episode_*.mp4")):
        encode_h264(pred, [np.concatenate([flat(render_level(s), MOSAIC_VIEW, MOSAIC_VIEW),
                                           flat(predicted_level(s), MOSAIC_VIEW, MOSAIC_VIEW)], axis=1)
                           for s in range(24)], fps=10, crf=18)
    return root


@pytest.fixture(scope="module")
def layouts(tmp_path_factory, dz_layout, dz_layout_session) -> dict[str, Path]:
    """Every layout the repository's tests build, by name (each written once for the module)."""
    root = tmp_path_factory.mktemp("strict-json")
    served = root / "served" / "video_pred_output"
    save_prediction(served, "put the cube in the bowl", served_frames(4), WHEN)
    save_prediction(served, "", served_frames(2), WHEN + datetime.timedelta(seconds=30))
    runs = root / "served" / "runs"
    save_client_episode(runs, 0, 36)
    save_client_episode(runs, 1, 20)
    offline = root / "offline"
    offline.mkdir()
    write_run(offline / "ar3", 3)
    write_run(offline / "one", 1, seed=1, mp4=False)
    evaluation = root / "eval"
    write_eval(evaluation, {("so101_sim", 0): [True, False], ("so101_sim", 1): [True]})
    log = lambda _: None  # noqa: E731
    found = {
        "demo": DEMO,
        "demo_copy": demo_copy(root / "copy", {"seam_jump", "single_f000", "video_degrades"}),
        "lerobot_v30": LEROBOT / "so101_v30",
        "lerobot_v21": LEROBOT / "so101_v21",
        "dreamzero_so101": dz_layout,
        "dreamzero_so101_session": dz_layout_session,
        "served": served,
        "served_session": import_served(served, root / "served_session", recording=runs, log=log)[0],
        "offline": offline,
        "eval": evaluation,
        "eval_session": import_eval(evaluation, root / "eval_session", log=log)[0],
        "eval_mosaic": write_mosaic_eval(root / "mosaic"),
        "groot_dreams": write_groot_dreams(root / "gd" / "so100.data_idm", [("pick", 40), ("place", 30)]),
    }
    if real_outputs_skip_reason() is None:
        found["real_dreamzero_so101"] = real_fixtures_dir() / "dreamzero_so101"
    return found


# the layouts `info` describes (a DreamZero-SO101 evaluation root is read by report and compare)
INFO_LAYOUTS = ("demo", "lerobot_v30", "lerobot_v21", "dreamzero_so101_session", "served", "served_session",
                "offline", "eval", "eval_session", "eval_mosaic", "groot_dreams")
# the demo's rollouts of every kind (a single chunk, seams, a breaking video) in a copy: its 17
# rollouts take ~20 s to report on a busy 2-core machine, its three ~5 s
REPORT_LAYOUTS = tuple(n for n in INFO_LAYOUTS if n != "demo") + ("demo_copy", "dreamzero_so101",
                                                                  "real_dreamzero_so101")
# pairs `compare` pairs rollout by rollout (by tag: a layout and its import, or a layout with itself)
COMPARED = (("demo_copy", "demo_copy"), ("dreamzero_so101", "dreamzero_so101_session"),
            ("served", "served_session"), ("offline", "offline"), ("eval", "eval_session"))


def _layout(layouts: dict[str, Path], name: str) -> Path:
    if name not in layouts:
        pytest.skip(str(real_outputs_skip_reason()))
    return layouts[name]


@pytest.mark.slow
@pytest.mark.parametrize("name", INFO_LAYOUTS)
def test_info_json_is_strict(layouts, name):
    info = cli("info", "--json", _layout(layouts, name))
    assert isinstance(info, dict) and info


@pytest.mark.slow
@pytest.mark.parametrize("name", REPORT_LAYOUTS)
def test_report_json_is_strict_with_and_without_sanity(layouts, name):
    path = _layout(layouts, name)
    report = cli("report", "--json", "--jobs", "1", path)
    assert any(report.get(k) for k in ("rollouts", "episodes", "neural_trajectories")), report.keys()
    # the second reads the first's rows back from the cache, and adds the five-test verdict
    with_sanity = cli("report", "--json", "--sanity", "--jobs", "1", path)
    assert "sanity" in with_sanity


@pytest.mark.slow
@pytest.mark.parametrize(("a", "b"), COMPARED, ids=[f"{a}-{b}" for a, b in COMPARED])
def test_compare_json_is_strict(layouts, a, b):
    comparison = cli("compare", "--json", "--jobs", "1", layouts[a], layouts[b])
    assert comparison["pairs"], comparison.keys()


@pytest.mark.slow
def test_rank_and_agreement_json_is_strict(tmp_path):
    # imagined rates all alike (no rank to agree with) and one session winning every vote: the
    # degenerate inputs whose statistics have no finite value
    imagined = [write_decision_session(tmp_path / f"imagined_{c}", c, {t: 2 for t in TASKS}) for c in CHECKPOINTS]
    real = [write_decision_session(tmp_path / f"real_{c}", c, {t: i for t in TASKS})
            for i, c in enumerate(CHECKPOINTS)]
    agreement = cli("agreement", "--json", "--bootstrap", "200", "--imagined", *imagined, "--real", *real)
    assert agreement["points"]
    assert cli("rank", "--json", "--bootstrap", "200", *real)["ranking"]  # no votes: by success rate
    strong, weak = real[2], real[0]
    for i in range(6):
        save_vote(new_vote(Side(str(strong.resolve()), strong.name, f"t0_r{i % 4:02d}"),
                           Side(str(weak.resolve()), weak.name, "t0_r03"), "a"))
    ranked = cli("rank", "--json", "--bootstrap", "200", *real)
    assert ranked["method"] == "bradley_terry" and ranked["ranking"][0]["session"] == strong.name
    for path in [*tmp_path.rglob("*.json")]:  # session, rollout, outcome and vote files
        strict_json(path.read_text())


@pytest.mark.slow
def test_files_an_import_writes_are_strict(layouts):
    for name in ("served_session", "eval_session", "dreamzero_so101_session"):
        written = sorted(layouts[name].rglob("*.json"))
        assert any(p.name == "session.json" for p in written), name
        for path in written:
            strict_json(path.read_text())


@pytest.mark.slow
def test_a_video_only_rollout_has_no_seams_and_its_card_says_so(layouts):
    report = cli("report", "--json", "--sanity", "--jobs", "1", layouts["served_session"])
    chained = [r for r in report["rollouts"] if r["kind"] == "autoregressive"]
    assert chained and all(r["video_only"] for r in chained)
    for row in chained:
        # no measure ran on the actions that are not there
        assert row["seams"] is None and row["completion"] is None and row["rmse_deg"] is None, row["tag"]
        assert row["video_psnr_db"], row["tag"]  # ... while the video is compared with the recording
    session = open_session(layouts["served_session"])
    tl = build_timeline(next(iter(session.rollouts.values())))
    rows = dict(headline_metrics(tl, {v: tl.video_metrics(v).psnr_db for v in tl.video_views()}))
    assert rows["chunk seams"] == "not measured: no predicted actions (video only)"
    assert rows["joint measures"] == "not measured: no predicted actions (video only)"
    assert not any("nan" in f"{k} {v}".lower() for k, v in rows.items()), rows
    assert not any(k.startswith("steps past a joint limit") for k in rows), rows


@pytest.mark.slow
def test_frames_of_another_geometry_are_not_compared(layouts, tmp_path):
    expected = f"imagined {2 * MOSAIC_VIEW}x{MOSAIC_VIEW} vs GT {W}x{H}: different geometry; not compared"
    report = cli("report", "--json", "--jobs", "1", layouts["eval_mosaic"])
    for row in report["rollouts"]:
        assert row["video_psnr_db"] == {} and row["video_per_chunk"] == {}, row["tag"]
        assert row["video_psnr_note"] == {"render": expected}, row["tag"]
        assert row["video_action"] is None, row["tag"]
    assert report["aggregate"]["mean_video_psnr_db"] == {}
    # the card says the same, in place of a figure
    dest, _ = import_eval(layouts["eval_mosaic"], tmp_path / "s", log=lambda _: None)
    tl = build_timeline(next(iter(open_session(dest).rollouts.values())))
    rows = dict(headline_metrics(tl, {v: tl.video_metrics(v).psnr_db for v in tl.video_views()}))
    assert rows["video PSNR, render"] == expected and "video PSNR" not in rows
    # the predicted video split into the render's geometry (two 128x96 views) is compared
    split = cli("report", "--json", "--jobs", "1", layouts["eval_session"])
    assert all(r["video_psnr_note"] == {} for r in split["rollouts"])


@pytest.mark.slow
def test_the_gt_scaled_uniformly_is_compared_and_another_aspect_is_not(tmp_path):
    levels = [40 + 20 * i for i in range(6)]
    imagined, same_aspect, other_aspect = (tmp_path / f"{n}.mp4" for n in ("imagined", "same", "other"))
    encode_h264(imagined, [flat(v, 48, 64) for v in levels], fps=10, crf=12)
    encode_h264(same_aspect, [flat(v + 2, 96, 128) for v in levels], fps=10, crf=12)  # 4:3, twice the size
    encode_h264(other_aspect, [flat(v + 2, 64, 64) for v in levels], fps=10, crf=12)  # 1:1
    clip = VideoClip(imagined)
    assert geometry_note(clip, VideoClip(same_aspect)) is None
    assert geometry_note(clip, VideoClip(other_aspect)) == "imagined 64x48 vs GT 64x64: different geometry; not compared"
    # a model that resizes each camera's whole frame (DreamZero) is compared at any aspect
    assert geometry_note(clip, VideoClip(other_aspect), whole_frame=True) is None
    scaled = compare_clips("front", [clip], VideoClip(same_aspect), lambda f: f)[0]
    assert scaled.note is None and np.all(scaled.psnr_db > 30) and scaled.match is not None
    refused = compare_clips("front", [clip, clip], VideoClip(other_aspect), lambda f: f, with_ssim=True,
                            whole_frame=[False, True])
    assert refused[0].note is not None and np.isnan(refused[0].psnr_db).all() and np.isnan(refused[0].ssim).all()
    assert refused[0].match is None and refused[0].quality is not None  # the no-reference measures stand
    assert refused[1].note is None and np.all(refused[1].psnr_db > 30)
    assert json.loads(json_text(refused[0].to_json()))["note"] == refused[0].note


def test_json_text_refuses_a_non_finite_number_naming_its_place():
    document = {"rollouts": [{"tag": "a", "seams": None}, {"tag": "b", "seams": {"worst": [0.5, math.nan]}}]}
    with pytest.raises(NotJsonError, match=r"^rollouts\[1\]\.seams\.worst\[1\]: a non-finite number is not JSON"):
        json_text(document)
    with pytest.raises(NotJsonError, match=r"^the document: "):
        json_text(-math.inf)
    ok = {"a": [1.0, None, {"b": 2}], "c": "NaN"}
    assert strict_json(json_text(ok, indent=2)) == ok


def test_the_strict_parser_refuses_what_json_dumps_lets_through():
    with pytest.raises(ValueError, match="NaN is not JSON"):
        strict_json(json.dumps({"x": math.nan}))
    with pytest.raises(ValueError, match="Infinity is not JSON"):
        strict_json(json.dumps([math.inf]))
