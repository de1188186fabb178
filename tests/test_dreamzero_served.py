"""DreamZero's served predictions (video_pred_output/NNNNNN_<prompt>_<time>.mp4), written as its
policy server writes them (tests/served_layout.py), read as video-only rollouts; with the client's
recording beside them, each imagined frame is compared with the recording's frame at the step it
shows. Every view of every frame carries its (frame number, view) in stripes, so the checks say
which frame landed where.
"""

from __future__ import annotations

import datetime
import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_processes import module_command_server
from hypothesis import given, settings
from hypothesis import strategies as st
from served_layout import read_stamp, save_client_episode, save_prediction, served_frames

from inspector.data.importers.dreamzero_served import Timing, distinct_tags, import_served, parse_grid, parse_name
from inspector.data.session import open_session
from inspector.data.video import VideoClip
from inspector.errors import InspectorError

WHEN = datetime.datetime(2026, 3, 14, 15, 9, 26)
PROMPT = "put the cube in the bowl"
CALLS = 4
RECORDED_STEPS = 36  # the episode ended during the 4th call's 8 actions (calls at steps 0, 8, 16, 24)
# the views as the DROID tiles hold them (the transform's view number) and as the client's video does
SERVED_VIEW = {"exterior_1": 0, "exterior_2": 1, "wrist": 2}
CLIENT_VIEW = {"exterior_1": 0, "wrist": 1, "exterior_2": 2}

# the commands run as processes forked from one that imported the CLI once
_command_server, _run_command = module_command_server()


def cli(*argv) -> subprocess.CompletedProcess:
    """``inspector *argv`` as a process (forked from one CLI start-up); reports and exports with ``--jobs 1`` (measured in the
    command's process: these tests are about the served files, not the worker pool)."""
    if argv[0] in ("report", "export"):
        argv = (*argv, "--jobs", "1")
    return _run_command(*argv, timeout=300)


def stamps(path: Path) -> list[tuple[int, int]]:
    return [read_stamp(rgb) for _, rgb in VideoClip(path).iter_frames()]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A served-prediction directory of two sessions and the client's run directory beside it."""
    root = tmp_path_factory.mktemp("served")
    out = root / "video_pred_output"
    save_prediction(out, PROMPT, served_frames(CALLS), WHEN)
    save_prediction(out, "", served_frames(2), WHEN + datetime.timedelta(seconds=30))
    runs = root / "runs" / "2026-03-14" / "15-08-00"
    save_client_episode(runs, 0, RECORDED_STEPS)
    save_client_episode(runs, 1, 20)
    return out, runs


@pytest.fixture(scope="module")
def imported(run, tmp_path_factory):
    out, runs = run
    dest = tmp_path_factory.mktemp("session") / "s"
    log: list[str] = []
    import_served(out, dest, recording=runs, log=log.append)
    return open_session(dest)


def test_the_servers_names_become_tags_and_prompts(run, imported):
    out, _ = run
    assert sorted(p.name for p in out.iterdir()) == ["000000_put_the_cube_in_the_bowl_03_14_15_09_26.mp4",
                                                     "000001_no_prompt_03_14_15_09_56.mp4"]
    first = imported.rollouts["000000_put_the_cube_in_the_bowl_03_14_15_09_26"]
    second = imported.rollouts["000001_no_prompt_03_14_15_09_56"]
    assert (first.prompt, second.prompt) == (PROMPT, "")
    assert not first.has_joints and first.kind == "autoregressive"
    assert (first.n_chunks, first.frames_per_chunk, first.executed_per_chunk, first.fps) == (CALLS, 8, 8, 15.0)
    assert first.views == sorted(SERVED_VIEW) and first.gt_views == sorted(SERVED_VIEW)


def test_each_view_is_cut_from_its_tile_and_the_conditioning_frame_left_out(imported):
    r = imported.rollouts["000000_put_the_cube_in_the_bowl_03_14_15_09_26"]
    for view, number in SERVED_VIEW.items():
        # frame 0 of the served video is the conditioning image; imagined frame f is served frame f + 1
        assert stamps(r.root / "video" / f"{view}.mp4") == [(f + 1, number) for f in range(8 * CALLS)], view


def test_each_imagined_frame_is_compared_with_the_recording_at_the_step_it_shows(imported):
    r = imported.rollouts["000000_put_the_cube_in_the_bowl_03_14_15_09_26"]
    # call k starts at step 8 k (open_loop_horizon 8); its frame j shows step 8 k + 3 (j + 1)
    # (24 actions over 8 frames); the client's frame t is what the cameras saw at step t
    expected = [8 * k + 3 * (j + 1) for k in range(CALLS) for j in range(8)]
    first_past_end = next(i for i, t in enumerate(expected) if t >= RECORDED_STEPS)
    assert expected[:first_past_end][-1] == 34 and first_past_end == 22  # call 2's 7th frame shows step 37
    for view, number in CLIENT_VIEW.items():
        assert stamps(r.root / "gt" / "video" / f"{view}.mp4") == [(t, number) for t in expected[:first_past_end]]
    rec = r.extra["recording"]
    assert rec["frame_of_imagined"] == expected[:first_past_end]
    assert rec["imagined_without_gt"] == 8 * CALLS - first_past_end


def test_report_gives_psnr_and_ssim_per_chunk(run, imported):
    out, runs = run
    result = cli("report", "--json", "--no-cache", imported.root)
    assert result.returncode == 0, result.stderr
    rows = {r["tag"]: r for r in json.loads(result.stdout)["rollouts"]}
    row = rows["000000_put_the_cube_in_the_bowl_03_14_15_09_26"]
    assert row["video_only"] and row["rmse_deg"] is None
    per_chunk = row["video_per_chunk"]["wrist"]
    # chunks 0 and 1 are compared (frames 0-21), chunk 2 in part, chunk 3 not at all
    assert [v is None for v in per_chunk["psnr_db"]] == [False, False, False, True]
    assert all(0 < s < 1 for s in per_chunk["ssim"][:3])
    # the served directory itself reads too (no recording: no GT, the views still shown)
    direct = cli("report", "--json", "--no-cache", out)
    assert direct.returncode == 0, direct.stderr
    assert {r["prompt"] for r in json.loads(direct.stdout)["rollouts"]} == {PROMPT, ""}
    info = cli("info", out)
    assert info.returncode == 0 and "DreamZero served predictions: 2 video(s)" in info.stdout, info.stderr


def test_a_frame_count_no_call_count_gives_is_one_line_and_the_rest_load(run, tmp_path):
    out = tmp_path / "video_pred_output"
    good = save_prediction(out, PROMPT, served_frames(2), WHEN)
    bad = save_prediction(out, "stack the blocks", served_frames(2, extra_frames=3), WHEN)
    result = cli("import", "dreamzero-served", out, "-o", tmp_path / "s")
    assert result.returncode == 2
    assert result.stderr.strip() == (f"error: {bad}: 20 frames: not 1 + 8 n (a conditioning frame, then 8 per "
                                     "inference call); --frames-per-call sets the frames each call adds")
    report = json.loads(cli("report", "--json", "--no-cache", out).stdout)
    assert [r["tag"] for r in report["rollouts"]] == [good.stem]
    assert bad.name in json.dumps(report["errors"]) and "not 1 + 8 n" in json.dumps(report["errors"])


def test_a_tile_layout_that_does_not_divide_the_frame_is_one_line(run, tmp_path):
    out, _ = run
    result = cli("import", "dreamzero-served", out, "-o", tmp_path / "s", "--views", "a,b,c;d,e,f")
    assert result.returncode == 2 and not (tmp_path / "s").exists()
    first = sorted(out.iterdir())[0]
    assert result.stderr.strip() == (f"error: {first}: tile layout 'a,b,c;d,e,f' (2 row(s) x 3 column(s)) "
                                     "does not divide the 640x320 frame")
    with pytest.raises(InspectorError, match="not one rectangle"):
        parse_grid("a,b;b,a")


def test_a_recording_shorter_than_the_dream_is_one_line_and_the_rest_load(run, tmp_path):
    out, _ = run
    runs = tmp_path / "runs"
    save_client_episode(runs, 0, RECORDED_STEPS)
    short = save_client_episode(runs, 1, 7)  # the 2nd session's 2nd call came at step 8
    result = cli("import", "dreamzero-served", out, "-o", tmp_path / "s", "--recording", runs)
    assert result.returncode == 2
    assert result.stderr.strip() == (f"error: {short}: 7 frames, but 000001_no_prompt_03_14_15_09_56.mp4's "
                                     "2 calls run to step 8 (frame 8 at 15 fps): the recording is shorter "
                                     "than the dream")
    dest, errors = import_served(out, tmp_path / "kept", recording=runs, keep_going=True, log=lambda _: None)
    assert list(errors) == ["000001_no_prompt_03_14_15_09_56"]
    assert list(open_session(dest).rollouts) == ["000000_put_the_cube_in_the_bowl_03_14_15_09_26"]


def test_timing_flags_move_the_pairing(run, tmp_path):
    out, runs = run
    one = sorted(out.iterdir())[0]
    dest, _ = import_served(one, tmp_path / "s", recording=runs / "episode_0.mp4", log=lambda _: None,
                            timing=Timing(executed_per_call=4, steps_per_frame=0.5))
    r = open_session(dest).rollouts["000000_put_the_cube_in_the_bowl_03_14_15_09_26"]
    expected = [round(4 * k + 0.5 * (j + 1)) for k in range(CALLS) for j in range(8)]
    assert [t for t, _ in stamps(r.root / "gt" / "video" / "wrist.mp4")] == expected
    assert np.array_equal(r.extra["timing"]["frame_steps"], [4 * k + 0.5 * (j + 1) for k in range(CALLS)
                                                             for j in range(8)])


def test_a_lerobot_recording_is_the_gt_and_its_actions_the_executed_arm(tmp_path):
    """The SO-101 mosaic (chosen by its 640x352 frames) against episode 1 of a dataset written by
    LeRobot, recorded at 30 fps: the control rate defaults to it."""
    dataset = Path(__file__).parent / "data" / "lerobot" / "so101_v21"
    out = tmp_path / "video_pred_output"
    save_prediction(out, "Pick the red cube", served_frames(3, layout="so101"), WHEN)
    dest, errors = import_served(out, tmp_path / "s", dataset=dataset, episode=1, log=lambda _: None)
    assert errors == {}
    r = next(iter(open_session(dest).rollouts.values()))
    assert r.views == ["front", "gripper", "top"] and r.gt_views == ["front"] and r.episode_index == 1
    assert stamps(r.root / "video" / "top.mp4") == [(f + 1, 1) for f in range(24)]
    from inspector.data.lerobot_dataset import LeRobotDataset

    episode = LeRobotDataset(dataset).episode(1)
    assert np.array_equal(r.gt_actions, episode.action) and r.fps == 30.0
    expected = [8 * k + 3 * (j + 1) for k in range(3) for j in range(8)]
    assert r.extra["recording"]["frame_of_imagined"] == expected
    recorded = dict(episode.video("front").iter_frames())
    carried = [rgb for _, rgb in VideoClip(r.root / "gt" / "video" / "front.mp4").iter_frames()]
    assert len(carried) == len(expected)
    def distance(shift: int) -> float:  # of the carried frames to the recorded ones ``shift`` steps on
        return float(np.mean([np.abs(rgb.astype(int) - recorded[t + shift].astype(int)).mean()
                              for rgb, t in zip(carried, expected)]))
    by_shift = {shift: distance(shift) for shift in range(-3, 4)}
    assert min(by_shift, key=by_shift.get) == 0


def test_export_of_a_served_session_verifies(imported, tmp_path):
    from test_export import rrd_verify

    tag = "000000_put_the_cube_in_the_bowl_03_14_15_09_26"
    out = cli("export", imported.root, "-o", tmp_path / "dream.rrd", "--no-cache", "--rollout", tag)
    assert out.returncode == 0, out.stderr
    files = sorted((tmp_path / "dream.rrd").glob("*.rrd")) if (tmp_path / "dream.rrd").is_dir() \
        else [tmp_path / "dream.rrd"]
    assert files
    for f in files:
        rrd_verify(f)


def test_names_that_make_the_same_tag_become_two_rollouts_each_with_its_own_tag(tmp_path):
    out = tmp_path / "video_pred_output"
    out.mkdir()
    # the server keeps only letters, digits and _-. of a prompt; a file renamed by hand (or copied
    # from elsewhere) may hold a space, which a tag spells as _ too
    frames = served_frames(1)
    spaced = save_prediction(out, "a_b", frames, WHEN).rename(out / "000003_a b_03_14_15_09_26.mp4")
    plain = save_prediction(out, "a_b", frames, WHEN).rename(out / "000003_a_b_03_14_15_09_26.mp4")
    result = cli("report", "--json", "--no-cache", out)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    tags = [r["tag"] for r in report["rollouts"]]
    assert len(tags) == 2 and len(set(tags)) == 2 and not report.get("errors")
    assert all(t.startswith("000003_a_b_03_14_15_09_26_") for t in tags)
    # the same names give the same tags on the next import, with another file beside them
    save_prediction(out, "something else", frames, WHEN)
    dest, errors = import_served(out, tmp_path / "s", log=lambda _: None)
    assert errors == {}
    again = open_session(dest)
    assert set(tags) <= set(again.rollouts)
    sources = {again.rollouts[t].extra["source"]["path"] for t in tags}
    assert sources == {str(spaced.resolve()), str(plain.resolve())}


@settings(max_examples=200, deadline=None)
@given(st.lists(st.text(alphabet="aAb _-.é", min_size=1, max_size=6), min_size=1, max_size=8))
def test_no_two_served_files_share_a_tag_whatever_their_names(prompts):
    names = [f"{i % 3:06}_{p}_03_14_15_09_26.mp4" for i, p in enumerate(prompts)]
    videos = [v for v in (parse_name(Path(n)) for n in dict.fromkeys(names)) if v is not None]
    tags = [v.tag for v in distinct_tags(videos)]
    assert len({t.lower() for t in tags}) == len(tags)
    assert all(re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,127}", t) for t in tags)
