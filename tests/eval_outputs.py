"""A small ``lerobot-eval`` output directory, laid out as ``lerobot_eval.py`` writes it.

``eval_info.json`` (per_task / per_group / overall), ``videos/<group>_<id>/eval_episode_N.mp4`` and
``pred_episode_N.mp4``, and ``recordings/<group>_<id>/``: a LeRobot v3.0 dataset per task with
unnamed 6-value ``observation.state`` / ``action`` and ``next.reward`` / ``next.success`` /
``next.done`` (written by the project's LeRobot writer). Frames are flat colours naming their step.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from inspector.data.lerobot_writer import EpisodeData, write_lerobot_dataset
from inspector.data.video import encode_h264

H, W = 96, 128


PREDICTED_OFFSET = 3  # grey levels between a near-render prediction and the render [0..255]


def render_level(step: int) -> int:
    return 10 + 7 * step


def predicted_level(step: int) -> int:
    return 240 - 6 * step


def camera_level(step: int) -> int:
    return 20 + 5 * step


def flat(level: int, h: int = H, w: int = W) -> np.ndarray:
    return np.full((h, w, 3), level % 256, np.uint8)  # levels wrap past 255 in long episodes


@dataclass
class Recorded:
    task: str
    success: bool
    sum_reward: float
    state: np.ndarray
    action: np.ndarray


def write_eval(root: Path, episodes_per_task: dict[tuple[str, int], list[bool]], steps: int = 24,
               record: bool = True, seed: int = 0, n_envs: int = 1,
               predicted_near_render: bool = False) -> dict[str, list[Recorded]]:
    """Write an output directory; returns what each task's episodes hold (in episode order).

    With ``n_envs`` > 1 each task's recording is one dataset per env (``env_<k>``): episode i ran
    in env i % n_envs, as lerobot-eval's batched envs do.

    With ``predicted_near_render`` the predicted video's first view (its left half) is the render's
    frame of the same step plus :data:`PREDICTED_OFFSET` grey levels: paired with the right render
    frame its PSNR is 20 log10(255 / PREDICTED_OFFSET) dB; one step off, much lower."""
    rng = np.random.default_rng(seed)
    root.mkdir(parents=True)
    per_task, out = [], {}
    for (group, task_id), successes in episodes_per_task.items():
        task = f"{group}_{task_id}"
        vdir = root / "videos" / task
        vdir.mkdir(parents=True)
        recs, episodes, video_paths, pred_paths = [], [], [], []
        for k, success in enumerate(successes):
            t = np.arange(steps)[:, None]
            action = np.array([0.0, -30, 40, 50, 0, 20]) + 20 * np.sin(t / 7 + rng.uniform(0, 6, 6))
            action[3, 1] = -125.0  # shoulder_lift past its limit once: a commanded finding
            state = action + rng.normal(0, 1.0, action.shape)  # the arm lags a little behind
            reward = np.zeros(steps, np.float32)
            if success:
                reward[-3:] = 1.0
            recs.append(Recorded(task, success, float(reward.sum()), state, action))
            done = np.zeros(steps, bool)
            done[-1] = True
            episodes.append(EpisodeData(f"pick the cube ({task})", state, action,
                                        {"top": np.stack([flat(camera_level(s)) for s in range(steps)])},
                                        columns={"next.reward": reward,
                                                 "next.success": np.asarray(reward > 0),
                                                 "next.done": done}))
            # what lerobot-eval stores: the path as written from its working directory
            video = vdir / f"eval_episode_{k}.mp4"
            encode_h264(video, [flat(render_level(s)) for s in range(steps)], fps=10, crf=18)
            video_paths.append(f"outputs/eval/2026-11-24/run/videos/{task}/eval_episode_{k}.mp4")
            pred = vdir / f"pred_episode_{k}.mp4"
            if predicted_near_render:
                frames = [np.concatenate([flat(render_level(s) + PREDICTED_OFFSET), flat(predicted_level(s))], axis=1)
                          for s in range(steps)]
            else:
                frames = [flat(predicted_level(s), H, 2 * W) for s in range(steps)]
            encode_h264(pred, frames, fps=10, crf=18)
            pred_paths.append(str(pred))
        if record and n_envs == 1:
            write_lerobot_dataset(root / "recordings" / task, episodes, fps=10, units=None, joint_names=False)
        elif record:
            for k in range(n_envs):
                write_lerobot_dataset(root / "recordings" / task / f"env_{k}", episodes[k::n_envs], fps=10,
                                      units=None, joint_names=False)
        per_task.append({"task_group": group, "task_id": task_id, "metrics": {
            "sum_rewards": [r.sum_reward for r in recs], "max_rewards": [float(r.success) for r in recs],
            "successes": successes, "video_paths": video_paths, "predicted_video_paths": pred_paths}})
        out[task] = recs
    all_succ = [s for e in episodes_per_task.values() for s in e]
    (root / "eval_info.json").write_text(json.dumps({
        "per_task": per_task,
        "per_group": {},
        "overall": {"pc_success": 100 * float(np.mean(all_succ)), "n_episodes": len(all_succ)},
    }, indent=2))
    return out
