"""Small DreamZero-SO101 offline-inference runs, written as ``offline_inference.py`` writes them.

``predicted_actions.csv`` (``%.8f``), the 2x2 mosaic ``predicted_video.mp4`` (640x352 of 320x176
views; libx264 through PyAV), ``frames/`` (mosaic and per-view PNGs) and ``metadata.json``. Every
frame's views are flat colours that name the frame, so a test can tell which file frame it sees.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
from PIL import Image

from inspector.data.video import encode_h264
from inspector.units import JOINT_NAMES

VIEW_W, VIEW_H = 320, 176


def front_level(frame: int) -> int:
    """The grey level of the front view in mosaic frame ``frame`` (9 apart: survives H.264)."""
    return 10 + 9 * frame


def mosaic(frame: int) -> np.ndarray:
    out = np.zeros((2 * VIEW_H, 2 * VIEW_W, 3), np.uint8)
    out[:VIEW_H, :VIEW_W] = front_level(frame)
    out[:VIEW_H, VIEW_W:] = (200, 60, 40)  # top
    out[VIEW_H:, :VIEW_W] = (40, 90, 200)  # gripper
    return out  # bottom-right stays black


def chunk_actions(n_chunks: int, seed: int = 0) -> np.ndarray:
    """(n_chunks * 24, 6) smooth joints in degrees (gripper 0..100), some past the URDF limits."""
    rng = np.random.default_rng(seed)
    t = np.arange(24 * n_chunks)[:, None]
    base = np.array([5.0, -20.0, 30.0, 40.0, -10.0, 30.0])
    out = base + 15 * np.sin(t / 17 + rng.uniform(0, 6, 6)) + rng.normal(0, 0.5, (len(t), 6))
    out[5::24, 0] = 125.0  # shoulder_pan past its 110 deg limit once a chunk: a finding to count
    return out


def write_run(path: Path, n_chunks: int, *, seed: int = 0, mp4: bool = True, pngs: bool = True,
              column_order: tuple[str, ...] = JOINT_NAMES, prompt: str = "Pick the red cube",
              sidecar: dict | None = None) -> np.ndarray:
    """Write one run at ``path``; returns its (n_chunks * 24, 6) actions in JOINT_NAMES order."""
    path.mkdir(parents=True)
    actions = chunk_actions(n_chunks, seed)
    with (path / "predicted_actions.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("step", *column_order))
        for step, row in enumerate(actions):
            by_name = dict(zip(JOINT_NAMES, row))
            w.writerow((step, *(f"{float(by_name[j]):.8f}" for j in column_order)))
    n_frames = 8 * n_chunks + 1
    frames = [mosaic(f) for f in range(n_frames)]
    if pngs:
        for view in ("front", "top", "gripper"):
            (path / "frames" / view).mkdir(parents=True)
        for i, fr in enumerate(frames):
            Image.fromarray(fr).save(path / "frames" / f"frame_{i:03d}.png")
            for view, (r, c) in {"front": (0, 0), "top": (0, 1), "gripper": (1, 0)}.items():
                Image.fromarray(fr[r * VIEW_H:(r + 1) * VIEW_H, c * VIEW_W:(c + 1) * VIEW_W]).save(
                    path / "frames" / view / f"frame_{i:03d}.png")
    start = actions[0] - 1.0
    (path / "metadata.json").write_text(json.dumps({
        "prompt": prompt,
        "input_joint_positions": dict(zip(JOINT_NAMES, start.tolist())),
        "action_seed": 1140, "action_seeds": [1140 + i for i in range(n_chunks)],
        "chunk_count": n_chunks, "actions_per_chunk": 24, "num_inference_steps": 16,
        "action_shape": [24 * n_chunks, 6], "video_latent_shapes": [[1, 16, 3, 44, 80]] * n_chunks,
        "decoded_frame_count": n_frames,
        "frame_zero_includes_conditioning_image": True,
        "subsequent_chunks_drop_conditioning_frame": True,
    }, indent=2))
    if mp4:
        encode_h264(path / "predicted_video.mp4", frames, fps=30, crf=18)
    if sidecar is not None:
        (path / "inspector_gt.json").write_text(json.dumps(sidecar))
    return actions
