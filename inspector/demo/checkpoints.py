"""Checkpoint-like evaluations derived from the bundled demo: inputs for the README's workflows that
need more than one session (``compare``, ``serve --ab``, ``rank``, ``agreement``, ``outcomes import``).

``inspector demo --checkpoints`` writes, under a directory (the current one by default)::

    sessions/step-56000/      imagined evaluations of three checkpoints of one "model": the demo's
    sessions/step-64000/        clean rollouts (prompt_train's path, the six single chunks) with a
    sessions/step-72000/        known error added; outcomes labelled (source ``label``), votes
    robot/step-56000/         the same checkpoints "on the robot": the same rollouts without video,
    robot/step-64000/           outcomes from a run sheet (source ``file``)
    robot/step-72000/
    judge.jsonl               a judge's verdicts on step-72000's imagined rollouts

The differences are known, so each workflow has something to find:

- every rollout's joints get an error on the five arm joints, seeded by checkpoint and rollout:
  a random walk over the chunks of an autoregressive rollout, an offset growing along the horizon
  of a single chunk. Its typical size at the end (``ERROR_SCALE_DEG``: 7, 3.5 and 1 deg per joint)
  falls with training, so step-56000 is measurably worse than step-72000 rollout by rollout, and
  step-64000 sits between them;
- a rollout's *final error* (the largest arm-joint offset at its last executed step) decides its
  outcomes: success in imagination below ``IMAGINED_SUCCESS_DEG``, on the robot below the harsher
  ``REAL_SUCCESS_DEG`` (imagination is a little optimistic, as world models are); progress falls
  linearly to 0 at ``ZERO_PROGRESS_DEG``;
- the votes say the rollout with the smaller final error was better (a tie within ``TIE_DEG``),
  as a careful viewer of the two would; the judge's verdicts disagree with the labels on a
  few rollouts (the judge is stricter).

Everything lands atomically, per session; an existing destination is refused unless
``overwrite`` (it may hold labels or votes a person made).
"""

from __future__ import annotations

import os
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .._files import mkstemp_sibling
from ..data.session import Session, SessionWriter, check_replaceable, open_session
from ..data.sources import BUNDLED_DEMO
from ..errors import InspectorError
from ..outcomes import import_outcomes, outcomes_path
from ..said.outcome_store import store_records
from ..said.votes import Side, new_vote, save_vote
from ..schema import json_text

CHECKPOINTS = (56000, 64000, 72000)
ERROR_SCALE_DEG = {56000: 7.0, 64000: 3.5, 72000: 1.0}  # a rollout's typical final error per joint [deg]
IMAGINED_SUCCESS_DEG = 7.5
REAL_SUCCESS_DEG = 6.0
ZERO_PROGRESS_DEG = 20.0
TIE_DEG = 1.0
JUDGE_STRICTER_DEG = 2.0  # the judge's threshold sits this far below the labels'
MODEL_NAME = "demo-wam"
ARM = slice(0, 5)  # shoulder_pan .. wrist_roll; the gripper is left alone
AUTOREGRESSIVE_BASE = "prompt_train"
AUTOREGRESSIVE_COPIES = 6  # same start, different seeds: a success rate per checkpoint
RUN_SHEET = "robot_runs.csv"


@dataclass(frozen=True)
class DerivedRollout:
    tag: str
    base: str  # the demo rollout it starts from
    seed: int


def derived_rollouts(demo: Session) -> list[DerivedRollout]:
    """The rollouts every checkpoint holds: copies of prompt_train and each single chunk."""
    out = [DerivedRollout(f"red_cube_{i}", AUTOREGRESSIVE_BASE, i) for i in range(AUTOREGRESSIVE_COPIES)]
    singles = sorted(t for t, r in demo.rollouts.items() if r.kind == "single_chunk")
    out += [DerivedRollout(f"bowl_{t.removeprefix('single_')}", t, 100 + i) for i, t in enumerate(singles)]
    return out


def perturbed(actions: npt.NDArray[np.float64], executed: int, scale: float,
              seed: int) -> tuple[npt.NDArray[np.float64], float]:
    """``actions`` with the checkpoint's error added, and the rollout's final error [deg].

    Autoregressive: a random walk, one step per chunk, reached linearly over the chunk's steps (no
    jump at a seam); its steps shrink with the number of chunks so that the final error's typical
    size is ``scale`` whatever the length. A single chunk: an offset growing along its horizon to
    about ``scale``.
    """
    rng = np.random.default_rng(seed)
    n_chunks, horizon, _ = actions.shape
    out = actions.copy()
    if n_chunks == 1:
        direction = rng.normal(0.0, 1.0, 5)
        offset = np.linspace(0.0, 1.0, horizon)[:, None] * direction * scale
        out[0, :, ARM] += offset
        return out, float(np.abs(offset[-1]).max())
    walk = np.cumsum(rng.normal(0.0, scale / np.sqrt(n_chunks), (n_chunks, 5)), axis=0)
    before = np.vstack([np.zeros((1, 5)), walk[:-1]])
    ramp = np.clip(np.arange(horizon) / max(executed - 1, 1), 0.0, 1.0)[None, :, None]
    offset = before[:, None, :] + ramp * (walk - before)[:, None, :]
    out[:, :, ARM] += offset
    return out, float(np.abs(walk[-1]).max())


def _outcome(final_error: float, success_below: float) -> dict[str, object]:
    success = final_error < success_below
    progress = round(100.0 * max(0.0, 1.0 - final_error / ZERO_PROGRESS_DEG), 1)
    return {"success": success, "progress": 100.0 if success else progress,
            "failure": None if success else "missed_grasp"}


def _seed(step: int, rollout_seed: int) -> int:
    return zlib.crc32(f"{step}:{rollout_seed}".encode())


def write_checkpoints(root: Path, demo_path: Path = BUNDLED_DEMO, overwrite: bool = False,
                      log: Callable[[str], None] = print) -> list[Path]:
    """Write the sessions and the judge file described in the module docstring under ``root``.

    Returns:
        The paths written.

    Raises:
        InspectorError: a destination exists (and not ``overwrite``), or the demo cannot be read.
    """
    demo = open_session(demo_path)
    dataset = demo.dataset_root
    if dataset is None:
        raise InspectorError(demo_path / "session.json", "gt_source.dataset: the demo names no dataset")
    plan = derived_rollouts(demo)
    sessions = {step: root / "sessions" / f"step-{step}" for step in CHECKPOINTS}
    robots = {step: root / "robot" / f"step-{step}" for step in CHECKPOINTS}
    judge = root / "judge.jsonl"
    for dest in [*sessions.values(), *robots.values()]:  # refuse before any work
        check_replaceable(dest, overwrite, "session", "session.json")
    if judge.exists() and not overwrite:
        raise InspectorError(judge, "exists; --overwrite replaces it")

    final_error: dict[tuple[int, str], float] = {}
    for step in CHECKPOINTS:
        model = {"name": MODEL_NAME, "checkpoint": f"step-{step}"}
        for side, dest in (("imagined", sessions[step]), ("robot", robots[step])):
            rel_dataset = Path(_relative(dataset, dest))
            with SessionWriter.create(dest, name=f"step-{step}", model=model,
                                      dataset=rel_dataset, units=demo.units, overwrite=overwrite) as writer:
                for d in plan:
                    base = demo.rollouts[d.base]
                    actions, err = perturbed(base.actions, base.executed_per_chunk, ERROR_SCALE_DEG[step],
                                             _seed(step, d.seed))
                    final_error[step, d.tag] = err
                    states = None
                    if base.states is not None:
                        states = np.vstack([base.states[:1], actions[:, base.executed_per_chunk - 1]])
                    videos = {v: base.root / "video" / f"{v}.mp4" for v in base.views} if side == "imagined" else {}
                    writer.add_rollout(d.tag, kind=base.kind, actions=actions, states=states, prompt=base.prompt,
                                       episode_index=base.episode_index, start_frame=base.start_frame,
                                       fps=base.fps, executed_per_chunk=base.executed_per_chunk,
                                       frames_per_chunk=base.frames_per_chunk, videos=videos,
                                       extra={"derived_from": f"demo/{d.base}",
                                              "error_scale_deg_per_chunk": ERROR_SCALE_DEG[step],
                                              "final_error_deg": round(err, 3)})
        labels = {d.tag: _outcome(final_error[step, d.tag], IMAGINED_SUCCESS_DEG) for d in plan}
        store_records(outcomes_path(open_session(sessions[step])), labels, source="label", set_by="demo")
        _write_run_sheet(robots[step], {d.tag: _outcome(final_error[step, d.tag], REAL_SUCCESS_DEG) for d in plan})
        log(f"wrote {sessions[step]} and {robots[step]} ({len(plan)} rollouts each)")
    _write_votes(sessions, plan, final_error)
    _write_judge(judge, plan, final_error)
    log(f"wrote {judge} (a judge's verdicts on sessions/step-72000) and the votes of {len(CHECKPOINTS)} sessions")
    return [*sessions.values(), *robots.values(), judge]


def _relative(target: Path, session: Path) -> str:
    """``target`` as seen from ``session``: the sessions keep working when the tree moves."""
    return os.path.relpath(target.resolve(), session.parent.resolve() / session.name)


def _write_run_sheet(robot: Path, outcomes: dict[str, dict[str, object]]) -> None:
    """The robot side's outcomes as a run sheet a lab keeps, imported as a user would."""
    sheet = robot / RUN_SHEET
    lines = ["tag,success,progress,failure,note"]
    for tag, o in outcomes.items():
        lines.append(f"{tag},{str(o['success']).lower()},{o['progress']},{o['failure'] or ''},robot run")
    sheet.write_text("\n".join(lines) + "\n", encoding="utf-8")
    import_outcomes(sheet, robot)


def _write_votes(sessions: dict[int, Path], plan: list[DerivedRollout],
                 final_error: dict[tuple[int, str], float]) -> None:
    """Votes between every pair of checkpoints on every rollout: the smaller final error wins."""
    steps = sorted(sessions)
    for i, a in enumerate(steps):
        for b in steps[i + 1:]:
            for d in plan:
                ea, eb = final_error[a, d.tag], final_error[b, d.tag]
                answer = "tie" if abs(ea - eb) < TIE_DEG else "a" if ea < eb else "b"
                save_vote(new_vote(Side(str(sessions[a].resolve()), f"step-{a}", d.tag, None),
                                   Side(str(sessions[b].resolve()), f"step-{b}", d.tag, None), answer,
                                   note="demo: the smaller final error wins"))


def _write_judge(judge: Path, plan: list[DerivedRollout], final_error: dict[tuple[int, str], float]) -> None:
    """A judge's JSON lines on step-72000, stricter than the labels; written whole or not at all."""
    step = CHECKPOINTS[-1]
    rows = []
    for d in plan:
        o = _outcome(final_error[step, d.tag], IMAGINED_SUCCESS_DEG - JUDGE_STRICTER_DEG)
        rows.append(json_text({"tag": d.tag, **o, "note": "judge: gripper closes on the cube" if o["success"]
                               else "judge: gripper misses the cube"}))
    fd, tmp = mkstemp_sibling(judge)
    try:
        with open(fd, "w", encoding="utf-8") as f:
            f.write("\n".join(rows) + "\n")
        Path(tmp).replace(judge)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
