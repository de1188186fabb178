"""Generate the bundled demo session: a MuJoCo SO-101 dataset and rollouts with planted faults.

The ground truth is a small LeRobot v3.0 dataset (written by our writer in LeRobot's layout) of
the SO-101 picking a cube and placing one in a bowl, rendered offscreen by MuJoCo. Each rollout
replays that real path through a known distortion, so the tests know what every metric must find:

======================  ==============================================================
tag                     planted fault
======================  ==============================================================
tempo_0.8x              the GT path at 0.8x speed (best-match ~0, tempo ~0.8)
bias_elbow              elbow_flex offset growing linearly to 15 deg
limits_wrist            wrist_flex pushed to 120 deg mid-rollout, gripper below 0
overrun_60chunks        60 chunks (540 steps) on a shorter episode: post-episode chunks
prompt_train/novel      same start; novel veers for 2 chunks, then the same path
video_ahead_1s          prompt_train's joints; its imagined video 1 s (30 frames) ahead of them
single_fNNN             single chunks along an episode, error growing with the horizon
seam_jump               shoulder_pan jumps 20 deg where chunk 12 takes over from chunk 11
early_wander            twice as fast from 10 s, holds at the final pose, wanders from 12.5 s
phase_lag_wrist         wrist_flex 10 steps (0.33 s) behind the GT; the other joints in phase
video_degrades          noise growing in the imagined video from chunk 12 on
======================  ==============================================================

The last four (the sanity measures' faults) are derived from the episode's path and
prompt_train's rendered frames (:func:`write_sanity_rollouts`), so they cost no rendering.

Imagined video is rendered from the *predicted* joints (cheap settings), then visibly degraded
(blur, colour shift, noise, a slight wobble) so it reads as imagined.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ..data.lerobot_writer import EpisodeData, write_lerobot_dataset
from ..data.session import RolloutKind, SessionWriter
from ..data.sources import BUNDLED_DEMO
from ..units import JOINT_NAMES, Units

DEMO_DIR = BUNDLED_DEMO  # what `inspector serve` opens with no path
DATASET_DIR = "dataset"  # inside the session directory, so the demo travels as one folder
HORIZON, EXECUTED, FPS = 24, 9, 30.0
VIDEO_LEAD_STEPS = 30  # video_ahead_1s: its imagined video runs this many steps ahead of its joints
SEED = 101


@dataclass
class _Episode:
    task: str
    action: npt.NDArray[np.float64]  # (T, 6)
    state: npt.NDArray[np.float64]
    frames: dict[str, npt.NDArray[np.uint8]]
    objects: dict[str, npt.NDArray[np.float64]]  # name -> (T, 7)


def rebuild_demo(out: Path | None = None, quick: bool = False, log: Callable[[str], None] = print) -> Path:
    """Regenerate the demo session at ``out`` (default ``sessions/demo``), replacing it atomically.

    Args:
        out: destination session directory.
        quick: a tiny version (small frames drawn from decimated meshes, fast motions, few
            rollouts) for tests.

    Returns:
        The session directory.
    """
    from .cameras import write_scene_cameras
    from .motions import default_layouts, pick_motion, place_in_bowl_motion  # deferred: MuJoCo
    from .scene import DemoScene

    started = time.perf_counter()
    out = Path(out) if out is not None else DEMO_DIR
    rng = np.random.default_rng(SEED)
    size = (64, 48) if quick else (320, 240)
    speed = 3.0 if quick else 1.25
    gt_scene = DemoScene(*size, msaa=0 if quick else 4, shadows=not quick, coarse_meshes=quick)
    imagined_scene = DemoScene(*size, msaa=0, shadows=False, coarse_meshes=quick)
    layouts = default_layouts()
    scripts = [("Pick the red cube", "pick", pick_motion),
               ("Pick the red cube and place it in the bowl", "place_in_bowl", place_in_bowl_motion)]
    episodes: list[_Episode] = []
    log(f"rendering {len(scripts)} GT episodes, then the rollouts' imagined video (MuJoCo offscreen; "
        f"{'a few seconds' if quick else 'about 10-15 min of CPU in all'})")
    for task, layout_name, motion in scripts:
        layout = layouts[layout_name]
        gt_scene.reset(layout)
        waypoints = _speed_up(motion(gt_scene, layout), speed)
        sim = gt_scene.simulate_episode(waypoints, fps=FPS, layout=layout)
        episodes.append(_Episode(task, sim.action, sim.state, sim.frames, sim.object_poses))
        log(f"episode {len(episodes) - 1}: {task!r}, {len(sim)} frames ({len(sim) / FPS:.1f} s) "
            f"[{_clock(time.perf_counter() - started)} elapsed]")

    with SessionWriter.create(out, name="demo", units=Units("degrees"), dataset=DATASET_DIR,
                              model={"name": "scripted demo model", "checkpoint": "planted faults"},
                              overwrite=True) as writer:

        write_lerobot_dataset(writer.root / DATASET_DIR,
                              [EpisodeData(e.task, e.state, e.action, e.frames) for e in episodes],
                              fps=int(FPS), units=Units("degrees"))  # LeRobot writes a whole fps
        write_scene_cameras(gt_scene, writer.root)  # the exact cameras: the overlays' ground truth
        train_frames: dict[str, npt.NDArray[np.uint8]] = {}
        specs = _rollout_specs(episodes, rng, quick)
        eta = RenderEstimate(sum(spec.shown_frames() for spec in specs))
        for spec in specs:
            ep = episodes[spec.episode]
            executed, chunks, path_time = spec.build(ep.action, rng)  # in turn with _imagine: one seeded stream
            shown = spec.shown_frames()
            frames = _imagine(imagined_scene, layouts, scripts[spec.episode][1], ep, executed[:shown],
                              path_time[:shown], rng)
            states = np.concatenate([executed[:1], chunks[:, EXECUTED - 1]]) if spec.kind == "autoregressive" else None
            writer.add_rollout(spec.tag, kind=spec.kind, actions=chunks, states=states, prompt=spec.prompt,
                               episode_index=spec.episode, start_frame=spec.start, fps=FPS,
                               executed_per_chunk=EXECUTED, frames_per_chunk=EXECUTED,
                               videos=frames, extra={"planted_fault": spec.fault})
            log(f"rollout {spec.tag}: {spec.fault} {eta.done(shown)}")
            if spec.tag == "prompt_train":
                _write_video_ahead(writer, spec, chunks, states, frames, log)
                train_frames = frames
        if train_frames:
            write_sanity_rollouts(writer, episodes[0].action, train_frames, log)
    size_mb = sum(f.stat().st_size for f in out.rglob("*") if f.is_file()) / 1e6
    log(f"demo session {out}: {size_mb:.1f} MB in {time.perf_counter() - started:.0f} s")
    return out


def _clock(seconds: float) -> str:
    return f"{int(seconds) // 60}:{int(seconds) % 60:02d}"


class RenderEstimate:
    """``[k/N frames, m:ss elapsed, ~m:ss left]`` for the rollouts' imagined video: the time left is
    the frames left at the rate measured so far (the frames of one rollout cost about the same)."""

    def __init__(self, total_frames: int) -> None:
        self.total, self.rendered, self.started = total_frames, 0, time.perf_counter()

    def done(self, frames: int) -> str:
        self.rendered += frames
        elapsed = time.perf_counter() - self.started
        left = elapsed / max(self.rendered, 1) * (self.total - self.rendered)
        return f"[{self.rendered}/{self.total} frames, {_clock(elapsed)} elapsed, ~{_clock(left)} left]"


def _write_video_ahead(writer: SessionWriter, spec: _Spec, chunks: npt.NDArray[np.float64],
                       states: npt.NDArray[np.float64] | None, frames: dict[str, npt.NDArray[np.uint8]],
                       log: Callable[[str], None]) -> None:
    """The video-action fault: ``spec``'s rollout (its joints as they are) whose imagined video
    shows each step :data:`VIDEO_LEAD_STEPS` steps early (the last frame held at the end). Derived
    from frames already rendered, so it costs no rendering and no random draw."""
    fault = f"imagined video {VIDEO_LEAD_STEPS / FPS:g} s ({VIDEO_LEAD_STEPS} frames) ahead of the predicted joints"
    ahead = {camera: f[np.minimum(np.arange(len(f)) + VIDEO_LEAD_STEPS, len(f) - 1)] for camera, f in frames.items()}
    writer.add_rollout("video_ahead_1s", kind=spec.kind, actions=chunks, states=states, prompt=spec.prompt,
                       episode_index=spec.episode, start_frame=spec.start, fps=FPS,
                       executed_per_chunk=EXECUTED, frames_per_chunk=EXECUTED, videos=ahead,
                       extra={"planted_fault": fault})
    log(f"rollout video_ahead_1s: {fault}")


# ----------------------------------------------------------------------------------------------
# The sanity measures' faults (seams, completion, joint coherence, video break)

SEAM_CHUNK, SEAM_JUMP_DEG = 12, 20.0  # seam_jump: shoulder_pan +20 deg from chunk 12 on
# early_wander: real speed until 10 s, then twice as fast to the end of the path, held there,
# wandering from 12.5 s
HURRY_FROM_S, HURRY_TEMPO, WANDER_FROM_S, WANDER_DEG = 10.0, 2.0, 12.5, 30.0
PHASE_LAG_STEPS = 10  # phase_lag_wrist: wrist_flex this many steps behind
DEGRADE_FROM_CHUNK = 12  # video_degrades: noise from this chunk on, growing
SANITY_SEED = SEED + 1  # its own draws: the older rollouts' stay as they were
SANITY_TAGS = ("seam_jump", "phase_lag_wrist", "video_degrades", "early_wander")


def write_sanity_rollouts(writer: SessionWriter, gt: npt.NDArray[np.float64],
                          train_frames: dict[str, npt.NDArray[np.uint8]], log: Callable[[str], None] = print) -> None:
    """Add the four rollouts whose faults the sanity measures must find, on episode 0 from frame 0.

    Args:
        gt: (G, 6) episode 0's actions.
        train_frames: prompt_train's imagined frames per camera (the GT path at real speed, one
            frame a step): the new rollouts show them re-timed, so nothing is rendered.
    """
    rng = np.random.default_rng(SANITY_SEED)
    j = {name: i for i, name in enumerate(JOINT_NAMES)}
    n_frames = min(len(f) for f in train_frames.values())
    end_time = len(gt) - 1

    def chunked(path_time: npt.NDArray[np.float64], n_chunks: int, shift=None) -> npt.NDArray[np.float64]:
        full = _sample(gt, path_time)
        if shift is not None:
            full = shift(full)
        full[:, :5] += rng.normal(scale=0.15, size=(len(full), 5))
        chunks = np.stack([full[k * EXECUTED:k * EXECUTED + HORIZON] for k in range(n_chunks)])
        chunks[:, EXECUTED:, :5] += rng.normal(scale=0.6, size=(n_chunks, HORIZON - EXECUTED, 5)).cumsum(axis=1)
        return chunks

    def shown(path_time: npt.NDArray[np.float64]) -> dict[str, npt.NDArray[np.uint8]]:
        index = np.clip(np.round(path_time).astype(int), 0, n_frames - 1)
        return {camera: f[index] for camera, f in train_frames.items()}

    def add(tag: str, fault: str, chunks: npt.NDArray[np.float64], videos: dict[str, npt.NDArray[np.uint8]]) -> None:
        states = np.concatenate([chunks[:1, 0], chunks[:, EXECUTED - 1]])
        writer.add_rollout(tag, kind="autoregressive", actions=chunks, states=states, prompt="Pick the red cube",
                           episode_index=0, start_frame=0, fps=FPS, executed_per_chunk=EXECUTED,
                           frames_per_chunk=EXECUTED, videos=videos, extra={"planted_fault": fault})
        log(f"rollout {tag}: {fault}")

    n = 25  # chunks: long enough for each fault, short enough to keep the demo small
    steps = np.arange(n * EXECUTED + HORIZON, dtype=np.float64)
    seam = chunked(steps, n)
    seam[SEAM_CHUNK:, :, j["shoulder_pan"]] += SEAM_JUMP_DEG
    add("seam_jump", f"shoulder_pan jumps {SEAM_JUMP_DEG:g} deg where chunk {SEAM_CHUNK} takes over", seam,
        shown(steps[: n * EXECUTED]))

    def lag_wrist(full: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        full[:, j["wrist_flex"]] = _sample(gt, steps - PHASE_LAG_STEPS)[:, j["wrist_flex"]]
        return full
    add("phase_lag_wrist", f"wrist_flex {PHASE_LAG_STEPS} steps ({PHASE_LAG_STEPS / FPS:.2f} s) behind the GT",
        chunked(steps, n, lag_wrist), shown(steps[: n * EXECUTED]))

    n_degrade = 18
    steps_d = np.arange(n_degrade * EXECUTED + HORIZON, dtype=np.float64)
    frames = shown(steps_d[: n_degrade * EXECUTED])
    noisy = {}
    for camera, f in frames.items():
        chunk = np.arange(len(f)) // EXECUTED
        sigma = np.where(chunk >= DEGRADE_FROM_CHUNK, 26.0 + 4.0 * (chunk - DEGRADE_FROM_CHUNK), 0.0)
        # grain of 2x2 pixels: as plain to the eye and to the measure, and cheaper to store
        grain = rng.normal(size=(len(f), -(-f.shape[1] // 2), -(-f.shape[2] // 2), 3)).astype(np.float32)
        grain = grain.repeat(2, axis=1).repeat(2, axis=2)[:, : f.shape[1], : f.shape[2]]
        noise = grain * sigma[:, None, None, None].astype(np.float32)
        noisy[camera] = np.clip(f.astype(np.float32) + noise, 0, 255).astype(np.uint8)
    add("video_degrades", f"imagined video noise growing from chunk {DEGRADE_FROM_CHUNK} on",
        chunked(steps_d, n_degrade), noisy)

    n_early = len(gt) // EXECUTED
    steps_e = np.arange(n_early * EXECUTED + HORIZON, dtype=np.float64)
    hurry = HURRY_FROM_S * FPS
    path_time = np.minimum(np.where(steps_e < hurry, steps_e, hurry + HURRY_TEMPO * (steps_e - hurry)), end_time)

    def wander(full: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        t = steps_e / FPS - WANDER_FROM_S
        full[:, j["shoulder_pan"]] += WANDER_DEG * np.sin(np.pi * np.clip(t / 1.5, 0, 1)) * (t > 0)
        return full
    add("early_wander", f"the path {HURRY_TEMPO:g}x as fast from {HURRY_FROM_S:g} s, held at its end, "
                        f"wandering from {WANDER_FROM_S:g} s",
        chunked(path_time, n_early, wander), shown(path_time[: n_early * EXECUTED]))


def plant_sanity_rollouts(session_dir: Path, log: Callable[[str], None] = print) -> None:
    """Add :func:`write_sanity_rollouts`' rollouts to an existing demo session (from its dataset
    and prompt_train's videos on disk), replacing them if there."""
    from ..data.lerobot_dataset import open_dataset
    from ..data.session import open_session

    session = open_session(session_dir)
    assert session.dataset_root is not None
    gt = open_dataset(session.dataset_root).episode(0).action
    train = session.rollouts["prompt_train"]
    frames = {view: train.video(view).decode() for view in train.views}
    with SessionWriter.append(session_dir) as writer:
        for tag in SANITY_TAGS:
            shutil.rmtree(Path(session_dir) / "rollouts" / tag, ignore_errors=True)
        write_sanity_rollouts(writer, np.asarray(gt, np.float64), frames, log)


def _speed_up(waypoints, speed: float):
    from dataclasses import replace

    return [replace(w, move_s=w.move_s / speed, hold_s=w.hold_s / speed) for w in waypoints]


# ----------------------------------------------------------------------------------------------
# Rollouts: a real path through a known distortion


@dataclass
class _Spec:
    tag: str
    kind: RolloutKind
    episode: int
    prompt: str
    fault: str
    n_steps: int
    start: int = 0
    tempo: float = 1.0
    offset: Callable[[npt.NDArray[np.integer]], npt.NDArray[np.float64]] | None = None  # (T,) step -> (T, 6)
    horizon_error: float = 0.0  # deg at the last horizon step (single chunks)

    def shown_frames(self) -> int:
        """Frames of imagined video: every executed step of an autoregressive rollout; a single
        chunk's executed steps, one frame each, as frames_per_chunk says (a real sample's 9
        frames): frames of the unexecuted tail would be read as later chunks' frames."""
        return -(-self.n_steps // EXECUTED) * EXECUTED if self.kind == "autoregressive" else EXECUTED

    def build(self, gt: npt.NDArray[np.float64], rng: np.random.Generator):
        """(executed (T, 6), chunks (N, H, 6), path time (T,) [GT frame]) for this rollout."""
        if self.kind == "single_chunk":
            steps = np.arange(HORIZON)
            path_time = self.start + steps.astype(float)
            chunk = _sample(gt, path_time)
            direction = rng.normal(size=6)
            direction /= np.linalg.norm(direction)
            chunk = chunk + (steps / (HORIZON - 1))[:, None] ** 1.5 * self.horizon_error * direction
            return chunk, chunk[None], path_time
        n_chunks = -(-self.n_steps // EXECUTED)
        steps = np.arange(n_chunks * EXECUTED + HORIZON)
        path_time = self.start + self.tempo * steps
        full = _sample(gt, path_time)
        if self.offset is not None:
            full = full + self.offset(steps)
        # A model is never exact: a little noise on the arm. Not on the gripper, whose GT sits at
        # its closed limit (0) while it holds the cube: noise there would cross the limit in every
        # rollout and bury the one rollout whose limit violations are planted.
        full[:, :5] += rng.normal(scale=0.15, size=(len(full), 5))
        chunks = np.stack([full[k * EXECUTED:k * EXECUTED + HORIZON] for k in range(n_chunks)])
        # the unexecuted tail of each chunk is a guess that wanders off a little
        chunks[:, EXECUTED:, :5] += rng.normal(scale=0.6, size=(n_chunks, HORIZON - EXECUTED, 5)).cumsum(axis=1)
        executed = chunks[:, :EXECUTED].reshape(-1, 6)
        return executed, chunks, path_time[: len(executed)]


def _sample(gt: npt.NDArray[np.float64], t: npt.NDArray[np.floating]) -> npt.NDArray[np.float64]:
    """GT joints at fractional frame times (held at the ends)."""
    frames = np.arange(len(gt))
    return np.stack([np.interp(t, frames, gt[:, j]) for j in range(gt.shape[1])], axis=1)


def _rollout_specs(episodes: list[_Episode], rng: np.random.Generator, quick: bool) -> list[_Spec]:
    j = {name: i for i, name in enumerate(JOINT_NAMES)}
    n0, n1 = len(episodes[0].action), len(episodes[1].action)
    steps0 = (n0 // EXECUTED) * EXECUTED

    def ramp_on(joint: str, final: float, n: int):
        return lambda s: np.outer(np.clip(s / n, 0, 1) * final, np.eye(6)[j[joint]])

    def limits(s):
        out = np.zeros((len(s), 6))
        bump = np.exp(-0.5 * ((s - 0.5 * steps0) / (0.08 * steps0)) ** 2)
        out[:, j["wrist_flex"]] = bump * (120.0 - 70.0)  # from ~70 deg up past the 95 deg limit
        out[:, j["gripper"]] = -25.0 * bump  # a gripper below fully closed, as raw outputs do
        return out

    def veer(s):
        out = np.zeros((len(s), 6))
        # two chunks towards the other cube, then back onto the same path as the training prompt
        out[:, j["shoulder_pan"]] = 25.0 * np.sin(np.pi * np.clip(s / (2 * EXECUTED), 0, 1))
        return out

    specs = [
        _Spec("tempo_0.8x", "autoregressive", 0, "Pick the red cube", "same path at 0.8x speed", steps0, tempo=0.8),
        _Spec("bias_elbow", "autoregressive", 0, "Pick the red cube", "elbow_flex bias growing to 15 deg",
              steps0, offset=ramp_on("elbow_flex", 15.0, steps0)),
        _Spec("limits_wrist", "autoregressive", 0, "Pick the red cube",
              "wrist_flex to 120 deg and gripper below 0 mid-rollout", steps0, offset=limits),
        _Spec("overrun_60chunks", "autoregressive", 1, "Pick the red cube and place it in the bowl",
              f"60 chunks (540 steps) on a {n1}-frame episode", 60 * EXECUTED),
        _Spec("prompt_train", "autoregressive", 0, "Pick the red cube", "training prompt", steps0),
        _Spec("prompt_novel", "autoregressive", 0, "Pick the blue cube",
              "novel prompt: veers for 2 chunks, then collapses onto the training path", steps0, offset=veer),
    ]
    starts = np.linspace(0, n1 - HORIZON - 1, 3 if quick else 6).astype(int)
    specs += [_Spec(f"single_f{s:03d}", "single_chunk", 1, episodes[1].task,
                    "single chunk, error growing along the horizon to 8 deg", HORIZON, start=int(s),
                    horizon_error=8.0) for s in starts]
    if quick:
        specs = [s for s in specs if s.tag in ("tempo_0.8x", "limits_wrist") or s.kind == "single_chunk"]
    return specs


# ----------------------------------------------------------------------------------------------
# Imagined video


def _imagine(scene, layouts, layout_name: str, ep: _Episode, executed: npt.NDArray[np.float64],
             path_time: npt.NDArray[np.float64], rng: np.random.Generator) -> dict[str, npt.NDArray[np.uint8]]:
    """Render the predicted joints (objects where the real ones were at that point of the path)."""
    from .scene import CAMERAS  # deferred: importing scene loads MuJoCo

    scene.reset(layouts[layout_name])
    frame_of = np.clip(np.round(path_time).astype(int), 0, len(ep.action) - 1)
    out = {}
    for camera in CAMERAS:
        frames = np.stack([
            scene.render(q, camera, {name: poses[f] for name, poses in ep.objects.items()})
            for q, f in zip(executed, frame_of)
        ])
        out[camera] = degrade(frames, rng)
    return out


# Frames :func:`degrade` works on at once (a few MB of floats each).
DEGRADE_BATCH = 16


def degrade(frames: npt.NDArray[np.uint8], rng: np.random.Generator) -> npt.NDArray[np.uint8]:
    """Make rendered frames look imagined: blur, a warm colour shift, noise, a slight wobble.

    Done a few frames at a time: the float copies of a whole clip (five of them, 0.4 GB each for
    a 15 s clip) cost more in memory traffic than the arithmetic; the noise is drawn in the same
    order, so the frames are the same as the whole clip's at once."""
    out = np.empty(frames.shape, np.uint8)
    tint = np.array([1.08, 0.97, 0.88], np.float32)
    # geometry wobble: each frame shifted by a slowly varying sub-frame offset
    shifts = np.round(2.0 * np.sin(np.arange(len(frames)) / 7.0)).astype(int)
    for start in range(0, len(frames), DEGRADE_BATCH):
        f: npt.NDArray[np.floating] = frames[start:start + DEGRADE_BATCH].astype(np.float32)
        # 3x3 box blur, separable
        f = (np.roll(f, 1, axis=1) + f + np.roll(f, -1, axis=1)) / 3
        f = (np.roll(f, 1, axis=2) + f + np.roll(f, -1, axis=2)) / 3
        f = f * tint + 6.0
        f = f + rng.normal(scale=5.0, size=f.shape).astype(np.float32)
        for i, img in enumerate(f, start):
            out[i] = np.clip(np.roll(img, shifts[i], axis=1), 0, 255).astype(np.uint8)
    return out
