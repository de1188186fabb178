"""A small source directory in the DreamZero-SO101 evaluation layout, made from the bundled demo.

What ``inspector import dreamzero-so101`` reads (see ``inspector/data/importers/dreamzero_so101.py``),
with the demo session's own predictions, imagined videos and GT (its LeRobot dataset) in it, so the
importer, the raw-source commands and the malformed-input cases run on what the repository owns.
The real model outputs (``$INSPECTOR_FIXTURES/dreamzero_so101``) are not redistributable; the
tests of their numbers use those when present.

The demo has two cameras, ``front`` and ``wrist``; here the wrist camera is the layout's
``gripper`` view (DreamZero-SO101's name for it). There is no ``top`` camera: the mosaic's top
quarter is black, like its fourth.

Layout written (names as the real outputs have them)::

    train_rollout/ep000_train/  the demo's overrun_60chunks (60 chunks of 9 steps on its 409-frame
                                episode 1): action_trace.npy (60, 24, 6), state_trace.npy (61, 6),
                                meta.json, rollout_{front,gripper}.mp4 (540 frames) and the episode's
                                gt_{front,gripper}.mp4 (409 frames); the gripper of chunks 20-22 is
                                planted past its limit (steps 0-7 at -40, limit -10), as the raw
                                model outputs leave their limits
    zeroshot_chunk/f000, f076, f153/
                                the demo's single_f000/f076/f153: meta.json with actions_pred and
                                actions_gt (24, 6, the dataset episode's actions), frame_in_ep,
                                state_in; pred_{front,gripper}.mp4 and gt_{front,gripper}.mp4
                                (9 frames)
    demo/train_ep0/             single_f000 as a mosaic sample: predicted_video.mp4 (2x2
                                [front|top; gripper|black], top black), gt_future.mp4 (front)

``write_aggregate`` adds a ``zeroshot_chunk/aggregate.json`` of the real schema (all samples,
some without a folder) to a copy of it.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from inspector.data.lerobot_dataset import open_dataset
from inspector.data.session import open_session
from inspector.data.video import decode, encode_h264
from inspector.units import JOINT_NAMES

DEMO = Path(__file__).resolve().parents[1] / "sessions" / "demo"
AR_TAG, AR_SOURCE = "ep000_train", "overrun_60chunks"
SINGLE = {"f000": "single_f000", "f076": "single_f076", "f153": "single_f153"}
MOSAIC_TAG, MOSAIC_SOURCE = "train_ep0", "single_f000"
VIEWS = {"front": "front", "gripper": "wrist"}  # layout view -> demo camera
GT_FRAMES = 9
LIMIT_CHUNKS, LIMIT_GRIPPER = slice(20, 23), -40.0


def write_dreamzero_layout(dest: Path, demo: Path = DEMO) -> Path:
    """Write the layout under ``dest`` (created) and return it."""
    session = open_session(demo)
    dataset = open_dataset(session.dataset_root)
    episodes: dict[int, object] = {}

    def episode(index: int):
        if index not in episodes:
            episodes[index] = dataset.episode(index)
        return episodes[index]

    # -- the autoregressive rollout
    r = session.rollouts[AR_SOURCE]
    ep = episode(r.episode_index)
    d = dest / "train_rollout" / AR_TAG
    d.mkdir(parents=True)
    actions = np.load(r.root / "actions.npy")
    actions[LIMIT_CHUNKS, :8, JOINT_NAMES.index("gripper")] = LIMIT_GRIPPER  # step 8 chains to the next state
    states = np.load(r.root / "states.npy")
    np.save(d / "action_trace.npy", actions)
    np.save(d / "state_trace.npy", states)
    _write_json(d / "meta.json", {
        "tag": AR_TAG, "episode": r.episode_index, "training_task": r.prompt, "prompt": r.prompt,
        "prompt_kind": "training", "episode_length": ep.length, "n_steps": int(actions.shape[0]),
        "frames_per_step": r.executed_per_chunk, "total_imagined_frames": int(actions.shape[0]) * r.frames_per_chunk,
        "initial_state": states[0].tolist(), "final_imagined_state": states[-1].tolist(),
        "n_completed_steps": int(actions.shape[0])})
    for view, camera in VIEWS.items():
        shutil.copyfile(r.root / "video" / f"{camera}.mp4", d / f"rollout_{view}.mp4")
        encode_h264(d / f"gt_{view}.mp4", (rgb for _, rgb in ep.clip_from(camera, 0).iter_frames()), ep.fps,
                    preset="veryfast")

    def sample(source: str, d: Path):
        """A single-chunk rollout's folder made at ``d``: the rollout, its episode, the folder, its
        predicted chunk and the GT actions of the same steps."""
        r = session.rollouts[source]
        ep = episode(r.episode_index)
        d.mkdir(parents=True)
        pred = np.load(r.root / "actions.npy")[0]
        return r, ep, d, pred, ep.action[r.start_frame:r.start_frame + pred.shape[0]]

    # -- single chunks, each with its GT joints and GT video from the dataset
    for tag, source in SINGLE.items():
        r, ep, d, pred, gt = sample(source, dest / "zeroshot_chunk" / tag)
        _write_json(d / "meta.json", {
            "tag": tag, "frame_in_ep": r.start_frame, "t_wall_s": r.start_frame / ep.fps,
            "actions_pred": pred.tolist(), "actions_gt": gt.tolist(),
            "state_in": ep.state[r.start_frame].tolist(),
            "action_rmse_deg": float(np.sqrt(np.mean((pred - gt) ** 2)))})
        for view, camera in VIEWS.items():
            shutil.copyfile(r.root / "video" / f"{camera}.mp4", d / f"pred_{view}.mp4")
            encode_h264(d / f"gt_{view}.mp4", _gt_frames(ep, camera, r.start_frame), ep.fps)

    # -- a mosaic sample
    r, ep, d, pred, gt = sample(MOSAIC_SOURCE, dest / "demo" / MOSAIC_TAG)
    front, _ = decode(r.root / "video" / "front.mp4")
    gripper, _ = decode(r.root / "video" / "wrist.mp4")
    black = np.zeros_like(front)
    mosaic = np.concatenate([np.concatenate([front, black], axis=2), np.concatenate([gripper, black], axis=2)], axis=1)
    encode_h264(d / "predicted_video.mp4", mosaic, ep.fps)
    encode_h264(d / "gt_future.mp4", _gt_frames(ep, "front", r.start_frame), ep.fps)
    _write_json(d / "meta.json", {
        "tag": MOSAIC_TAG, "episode": r.episode_index, "prompt": r.prompt, "episode_length": ep.length,
        "state": ep.state[r.start_frame].tolist(), "predicted_frames": int(front.shape[0]),
        "predicted_resolution": [int(mosaic.shape[1]), int(mosaic.shape[2])],
        "actions_pred": pred.tolist(), "actions_gt": gt.tolist()})
    return dest


TRAINING_DATASET = "lab/so101-training-mix"  # what the aggregates below say the model was trained on
ZERO_SHOT_DATASET = "lab/so101_unseen_task"


def write_aggregate(chunk_dir: Path, extra_samples: int = 2, seed: int = 0, **top: object) -> dict:
    """Write ``chunk_dir/aggregate.json`` in the schema of DreamZero-SO101's
    ``zeroshot_chunk/aggregate.json``: every sample folder's meta.json under ``chunk_dir`` as an
    entry, then ``extra_samples`` more (``sNNN``: a folder's actions moved by a random offset,
    with no folder), its figures computed from the entries. ``top`` overrides top-level fields.
    Returns what was written."""
    rng = np.random.default_rng(seed)
    samples = [json.loads((d / "meta.json").read_text()) for d in sorted(chunk_dir.iterdir())
               if (d / "meta.json").is_file()]
    for k in range(extra_samples):
        base = samples[k % len(samples)]
        pred = np.asarray(base["actions_pred"]) + rng.normal(0, 3, (len(base["actions_pred"]), len(JOINT_NAMES)))
        frame = base["frame_in_ep"] + 5 + k
        samples.append({**base, "tag": f"s{frame:03d}", "frame_in_ep": frame, "actions_pred": pred.tolist()})
    for s in samples:  # the repository's own figures, as its evaluation computes them
        diff = np.asarray(s["actions_pred"]) - np.asarray(s["actions_gt"])
        s.update(action_rmse_deg=float(np.sqrt(np.mean(diff ** 2))), action_mse_deg2=float(np.mean(diff ** 2)),
                 per_joint_rmse=np.sqrt(np.mean(diff ** 2, axis=0)).tolist(),
                 per_step_mse=np.mean(diff ** 2, axis=1).tolist(), video_psnr_db=18.0 + rng.random())
    rmse = [s["action_rmse_deg"] for s in samples]
    data = {"dataset": ZERO_SHOT_DATASET, "episode": 1, "episode_length": 409,
            "prompt": "Pick the red cube and place it in the bowl", "n_samples": len(samples),
            "sample_frames": [s["frame_in_ep"] for s in samples],
            "mean_action_rmse_deg": float(np.mean(rmse)), "median_action_rmse_deg": float(np.median(rmse)),
            "best_action_rmse_deg": float(np.min(rmse)), "worst_action_rmse_deg": float(np.max(rmse)),
            "mean_video_psnr_db": float(np.mean([s["video_psnr_db"] for s in samples])),
            "zero_shot_disclosure": f"Model was finetuned on {TRAINING_DATASET} only. This dataset was NOT in "
                                    "the training set.",
            "samples": samples, **top}
    _write_json(chunk_dir / "aggregate.json", data)
    return data


def _gt_frames(ep, camera: str, start: int) -> np.ndarray:
    """The episode's first ``GT_FRAMES`` frames of ``camera`` from ``start`` on."""
    frames = []
    for _, rgb in ep.clip_from(camera, start).iter_frames():
        frames.append(rgb)
        if len(frames) == GT_FRAMES:
            break
    return np.stack(frames)


def _write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=1) + "\n")
