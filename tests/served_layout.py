"""Write DreamZero served predictions the way its policy server does, and the client's recording.

The server (dreamzero0/dreamzero ``eval_utils/serve_dreamzero_wan22.py``, ``_save_predicted_video``)
names each video ``f"{len(existing):06}_{safe_prompt}_{timestamp}.mp4"`` and saves it with
``imageio.mimsave(path, list(frames), fps=5, codec="libx264")``; its frames tile the views as the
model's transform does (``groot/vla/model/dreamzero/transform/dreamzero_cotrain.py``
``_prepare_video``). The client (``eval_utils/run_sim_eval.py``) writes ``episode_N.mp4`` at 15 fps,
one frame per control step, each [right | wrist | left] at 224x224.

Every view of every frame shows stripes that encode (frame number, view): :func:`read_stamp`
decodes them from the H.264 frames, so a test can tell which frame landed where.
"""

from __future__ import annotations

import datetime
import os
from pathlib import Path

import imageio
import numpy as np

STRIPES = 10  # 7 bits of frame number, then 3 of view number
VIEW_BITS = 3
DROID_VIEWS = ("exterior_1", "exterior_2", "wrist")  # the transform's view 0, 1, 2
SO101_VIEWS = ("front", "top", "gripper")
CLIENT_VIEWS = ("exterior_1", "wrist", "exterior_2")  # run_sim_eval.py's [right | wrist | left]


def stamp(number: int, view: int, h: int, w: int) -> np.ndarray:
    """(h, w, 3) uint8 stripes: bit i of ``number * 8 + view`` (lowest first) white or black."""
    code = number * (1 << VIEW_BITS) + view
    frame = np.zeros((h, w, 3), np.uint8)
    edges = np.linspace(0, w, STRIPES + 1).round().astype(int)
    for i in range(STRIPES):
        if code >> i & 1:
            frame[:, edges[i]:edges[i + 1]] = 255
    return frame


def read_stamp(frame: np.ndarray) -> tuple[int, int]:
    """(frame number, view) of a :func:`stamp` frame, read at each stripe's centre."""
    w = frame.shape[1]
    centres = ((np.arange(STRIPES) + 0.5) * w / STRIPES).astype(int)
    bits = frame[:, centres].mean(axis=(0, 2)) > 127
    code = sum(1 << i for i, b in enumerate(bits) if b)
    return code >> VIEW_BITS, code & ((1 << VIEW_BITS) - 1)


def droid_tile(left_exterior: np.ndarray, right_exterior: np.ndarray, wrist: np.ndarray) -> np.ndarray:
    """_prepare_video's OXE_DROID layout (HWC here): the wrist view with its pixels repeated across
    the width over the full top row, the exteriors below."""
    h, w = wrist.shape[:2]
    out = np.zeros((2 * h, 2 * w, 3), np.uint8)
    out[:h, :] = np.repeat(wrist, 2, axis=1)
    out[h:, :w] = left_exterior
    out[h:, w:] = right_exterior
    return out


def so101_tile(front: np.ndarray, top: np.ndarray, gripper: np.ndarray) -> np.ndarray:
    """The SO-101 mosaic: [front | top; gripper | black]."""
    h, w = front.shape[:2]
    out = np.zeros((2 * h, 2 * w, 3), np.uint8)
    out[:h, :w], out[:h, w:], out[h:, :w] = front, top, gripper
    return out


def served_frames(n_calls: int, layout: str = "droid", frames_per_call: int = 8, extra_frames: int = 0
                  ) -> list[np.ndarray]:
    """1 + ``frames_per_call`` n frames (plus ``extra_frames``), frame f's views stamped (f, view)."""
    h, w = (160, 320) if layout == "droid" else (176, 320)
    frames = []
    for f in range(1 + frames_per_call * n_calls + extra_frames):
        views = [stamp(f, v, h, w) for v in range(3)]
        frames.append(droid_tile(*views) if layout == "droid" else so101_tile(*views))
    return frames


def save_prediction(output_dir: Path, prompt: str, frames: list[np.ndarray],
                    when: datetime.datetime | None = None) -> Path:
    """``_save_predicted_video``'s naming and encoding, line for line."""
    os.makedirs(output_dir, exist_ok=True)
    timestamp = (when or datetime.datetime.now()).strftime("%m_%d_%H_%M_%S")
    existing = [f for f in os.listdir(output_dir) if f.endswith(".mp4")]
    safe_prompt = prompt.replace(" ", "_")
    safe_prompt = "".join(c for c in safe_prompt if c.isalnum() or c in "_-.")
    if len(safe_prompt) > 80:
        safe_prompt = safe_prompt[:80]
    if not safe_prompt:
        safe_prompt = "no_prompt"
    output_path = os.path.join(output_dir, f"{len(existing):06}_{safe_prompt}_{timestamp}.mp4")
    imageio.mimsave(output_path, list(frames), fps=5, codec="libx264")
    return Path(output_path)


def save_client_episode(run_dir: Path, episode: int, n_steps: int) -> Path:
    """run_sim_eval.py's ``episode_N.mp4``: 15 fps, frame t (seen before action t) stamped (t, view)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    frames = [np.concatenate([stamp(t, v, 224, 224) for v in range(3)], axis=1) for t in range(n_steps)]
    path = run_dir / f"episode_{episode}.mp4"
    imageio.mimsave(path, frames, fps=15, codec="libx264")
    return path
