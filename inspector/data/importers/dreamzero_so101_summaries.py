"""What a DreamZero-SO101 checkout says about its samples beside their folders.

The evaluation writes, next to the per-sample folders, files that list samples and figures::

    zeroshot_chunk/aggregate.json   {dataset, episode, episode_length, prompt, n_samples, sample_frames,
                                     mean/median/best/worst_action_rmse_deg, mean_video_psnr_db,
                                     zero_shot_disclosure, samples: [{tag, frame_in_ep, actions_pred,
                                     actions_gt (24, 6), state_in, action_rmse_deg, per_joint_rmse,
                                     per_step_mse, video_psnr_db, ...}]}
    demo/all_metas.json, demo_mid/all_metas.json
                                    [meta, ...]: every sample's meta.json in one list
    train_rollout/honest_summary.json    [{tag, time_aligned_mean, ..., best_match_final, ep_end_sec}]
    train_rollout/drift_recomputed.json  {tag: {drift_vs_state_clipped_mean, ..., post_episode_dead_chunks}}
    train_rollout/summary.json           {rollouts: [meta, ...]}

A checkout may hold a sample only in such a list (its folder, with the videos, not shipped): the
importer reads it from the list, so every sample the evaluation reports is counted. The summary
files' figures are the repository's own: kept beside inspector's measurements, never used as one.
This module also decides which distribution a sample comes from (:func:`distribution_of`).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InspectorError, require
from ..session import json_too_large, read_json, read_json_object

AGGREGATE = "aggregate.json"
ALL_METAS = "all_metas.json"
INDEX_NAMES = (AGGREGATE, ALL_METAS)
# Figures an aggregate holds about all its samples (kept with each of them).
AGGREGATE_FIGURES = ("n_samples", "mean_action_rmse_deg", "median_action_rmse_deg", "best_action_rmse_deg",
                     "worst_action_rmse_deg", "mean_video_psnr_db")
# Top-level fields an aggregate lends each of its samples (a sample's own value wins).
AGGREGATE_CONTEXT = ("episode", "episode_length", "prompt")
# Per-rollout summary files beside the autoregressive rollouts, and the figures kept of each (its
# drift figures; summary.json repeats the rollouts' meta.json, kept for where the two differ).
TRAIN_SUMMARIES = {
    "honest_summary.json": ("time_aligned_mean", "time_aligned_final", "best_match_mean", "best_match_final",
                            "ep_end_sec"),
    "drift_recomputed.json": ("drift_vs_state_clipped_mean", "drift_vs_state_clipped_final",
                              "drift_vs_action_clipped_mean", "drift_vs_action_clipped_final", "best_match_mean",
                              "best_match_final", "min_dist_to_final_pose", "reached_within_tau", "tau_deg",
                              "n_chunks_in_episode", "n_chunks_after_episode", "post_episode_dead_chunks"),
    "summary.json": ("mean_drift_deg", "final_drift_deg"),
}
# The repository's folder names that say which distribution their samples come from.
ZERO_SHOT_DIRS = ("zeroshot_chunk",)
TRAINING_DIRS = ("train_rollout", "demo_mid")
TRAINING_TAG = re.compile(r"^(train|heldout)_ep\d+")  # demo/train_ep0, demo/heldout_ep50
# "Model was finetuned on whosricky/so101-megamix-v1 only": the training dataset, by its Hub id.
TRAINED_ON = re.compile(r"(?:fine-?tuned|trained)\s+on\s+([A-Za-z0-9][\w.-]*/[\w.-]*\w)", re.IGNORECASE)
ZERO_SHOT, TRAINING = "zero-shot", "training"


@dataclass
class SampleIndex:
    """An ``aggregate.json`` or ``all_metas.json``: its sample entries (as read, each checked when
    imported) and what the file says about all of them."""

    path: Path
    entries: list[Any]
    context: dict[str, Any] = field(default_factory=dict)
    figures: dict[str, Any] = field(default_factory=dict)
    dataset: str | None = None
    disclosure: str | None = None

    def where(self, i: int) -> str:
        """How entry ``i`` is named in messages: ``samples[3]`` (aggregate), ``[3]`` (a list)."""
        return f"samples[{i}]" if self.path.name == AGGREGATE else f"[{i}]"

    def tag(self, i: int) -> str | None:
        """Entry ``i``'s ``tag`` when it is a plain file name (a folder beside the index may hold it)."""
        entry = self.entries[i]
        tag = entry.get("tag") if isinstance(entry, dict) else None
        if isinstance(tag, str) and tag not in ("", ".", "..") and "/" not in tag and "\\" not in tag \
                and "\x00" not in tag:
            return tag
        return None

    def sample_meta(self, i: int) -> dict[str, Any]:
        """Entry ``i`` as a sample's meta.json: the aggregate's episode, length and prompt, then
        the entry's own fields."""
        entry = self.entries[i]
        require(isinstance(entry, dict), self.path, f"expected an object, found {type(entry).__name__}")
        return {**self.context, **entry}


def claims_index(path: Path) -> bool:
    """True when ``path`` (named ``aggregate.json`` or ``all_metas.json``) looks like the
    evaluation's: a file too large or not JSON is claimed by its name, for its reader to refuse."""
    if path.name not in INDEX_NAMES or not path.is_file():
        return False
    if json_too_large(path):
        return True
    try:
        data = json.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError):
        return True
    if path.name == AGGREGATE:
        return isinstance(data, dict) and "samples" in data
    return isinstance(data, list) and any(isinstance(e, dict) and "actions_pred" in e for e in data)


def read_index(path: Path) -> SampleIndex:
    """Read an ``aggregate.json`` / ``all_metas.json`` (bounded, strict JSON).

    Raises:
        InspectorError: naming the file and the field: not JSON, a NaN, ``samples`` not a list,
            a top-level field of the wrong type.
    """
    if path.name == ALL_METAS:
        data = read_json(path)
        require(isinstance(data, list), path, f"expected a JSON list of sample metas, found {type(data).__name__}")
        return SampleIndex(path, list(data))
    data = read_json_object(path)
    require("samples" in data, path, "missing field 'samples'")
    require(isinstance(data["samples"], list), path,
            f"samples: expected a list, found {type(data['samples']).__name__}")
    for key in ("dataset", "zero_shot_disclosure", "prompt"):
        require(data.get(key) is None or isinstance(data[key], str), path,
                f"{key}: expected a string, found {data.get(key)!r}")
    context = {k: data[k] for k in AGGREGATE_CONTEXT if data.get(k) is not None}
    figures = {k: data[k] for k in AGGREGATE_FIGURES if _is_number(data.get(k))}
    return SampleIndex(path, list(data["samples"]), context, figures, data.get("dataset") or None,
                       (data.get("zero_shot_disclosure") or "").strip() or None)


def training_dataset(indexes: list[SampleIndex]) -> tuple[str, Path] | None:
    """(the training dataset's Hub id, the file that names it) from the first zero-shot
    disclosure that says what the model was trained on."""
    for index in indexes:
        found = TRAINED_ON.search(index.disclosure or "")
        if found:
            return found.group(1), index.path
    return None


def distribution_of(path: Path, tag: str, index: SampleIndex | None,
                    training: tuple[str, Path] | None, shown: Any) -> dict[str, Any]:
    """``{"distribution", "distribution_source", "dataset"?}`` for the sample or rollout at ``path``
    (its folder, or where its folder would be), or ``{}`` where nothing says.

    In order: an index's ``zero_shot_disclosure`` (zero-shot); an index's ``dataset`` against the
    training dataset a disclosure names (equal: training, else zero-shot); the repository's folder
    names (``zeroshot_chunk/``: zero-shot; ``train_rollout/``, ``demo_mid/``, ``train_ep*`` and
    ``heldout_ep*`` samples: training, held-out episodes being the training dataset's too).

    Args:
        index: the ``aggregate.json``/``all_metas.json`` that lists the sample or sits beside it.
        training: what :func:`training_dataset` found.
        shown: path -> the text naming it in messages.
    """
    trained = training[0] if training is not None else None
    if index is not None and index.disclosure is not None:
        return _marked(ZERO_SHOT, f"{shown(index.path)} zero_shot_disclosure", index.dataset)
    if index is not None and index.dataset is not None and training is not None:
        trained = training[0]
        same = index.dataset == trained
        return _marked(TRAINING if same else ZERO_SHOT,
                       f"{shown(index.path)} dataset {index.dataset} "
                       f"{'is' if same else 'is not'} the training dataset {trained} ({shown(training[1])})",
                       index.dataset)
    dataset = index.dataset if index is not None else None
    folder = path.parent.name
    if folder in ZERO_SHOT_DIRS:
        return _marked(ZERO_SHOT, f"the evaluation's zero-shot folder {folder}/", dataset)
    if folder in TRAINING_DIRS or TRAINING_TAG.match(tag) or TRAINING_TAG.match(path.name):
        held_out = "heldout" in path.name or "heldout" in tag
        why = (f"a held-out episode of the training dataset ({path.name})" if held_out
               else f"the evaluation's training-distribution samples ({folder}/{path.name})")
        return _marked(TRAINING, why, dataset or trained)
    return {}


def _marked(distribution: str, why: str, dataset: str | None) -> dict[str, Any]:
    return {"distribution": distribution, "distribution_source": why, **({"dataset": dataset} if dataset else {})}


def differences(meta: dict[str, Any], entry: dict[str, Any]) -> list[str]:
    """Where a folder's meta.json and its entry in an index disagree: ``["actions_pred (max |diff|
    3.2)", "frame_in_ep (84 vs 85)"]``; empty when they agree (to 1e-6)."""
    out = []
    for key in ("actions_pred", "actions_gt", "state_in"):
        if key not in meta or key not in entry:
            continue
        try:
            a, b = np.asarray(meta[key], dtype=np.float64), np.asarray(entry[key], dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            out.append(f"{key} (not comparable)")
            continue
        if a.shape != b.shape:
            out.append(f"{key} (shape {a.shape} vs {b.shape})")
        elif not np.allclose(a, b, rtol=0, atol=1e-6):
            out.append(f"{key} (max |diff| {float(np.nanmax(np.abs(a - b))):.3g})")
    for key in ("frame_in_ep", "episode"):
        if key in meta and key in entry and meta[key] != entry[key]:
            out.append(f"{key} ({meta[key]!r} vs {entry[key]!r})")
    return out


class TrainSummaries:
    """The per-rollout summary files of a ``train_rollout/`` folder, each read once per import."""

    def __init__(self, shown: Any) -> None:
        self._read: dict[Path, Any] = {}
        self._shown = shown

    def figures(self, rollout_dir: Path, tag: str) -> tuple[dict[str, Any], dict[str, str], list[str]]:
        """(figures keyed ``<file>:<field>``, {file: path}, notes on files that could not be read)
        for the rollout ``tag`` from the summary files beside its folder."""
        figures: dict[str, Any] = {}
        files: dict[str, str] = {}
        notes: list[str] = []
        for name, fields in TRAIN_SUMMARIES.items():
            path = rollout_dir.parent / name
            if not path.is_file():
                continue
            try:
                entry = _entry(self._load(path), name, tag)
            except InspectorError as exc:
                notes.append(f"the repository's {self._shown(path)} not read: {exc.what}")
                continue
            kept = {k: entry[k] for k in fields if entry is not None and (_is_number(entry.get(k))
                                                                          or isinstance(entry.get(k), bool))}
            if kept:
                figures.update({f"{name}:{k}": v for k, v in kept.items()})
                files[name] = str(path.resolve())
        return figures, files, notes

    def _load(self, path: Path) -> Any:
        if path not in self._read:
            try:
                self._read[path] = read_json(path)
            except InspectorError as exc:
                self._read[path] = exc
        found = self._read[path]
        if isinstance(found, InspectorError):
            raise found
        return found


def _entry(data: Any, name: str, tag: str) -> dict[str, Any] | None:
    """The rollout ``tag``'s entry in a summary file (None when it has none)."""
    if name == "drift_recomputed.json":
        if not isinstance(data, dict):
            raise InspectorError(name, f"expected an object keyed by rollout tag, found {type(data).__name__}")
        entry = data.get(tag)
        return entry if isinstance(entry, dict) else None
    if name == "summary.json":
        if not isinstance(data, dict) or not isinstance(data.get("rollouts"), list):
            raise InspectorError(name, "rollouts: expected a list of rollout metas")
        data = data["rollouts"]
    if not isinstance(data, list):
        raise InspectorError(name, f"expected a list of rollout entries, found {type(data).__name__}")
    return next((e for e in data if isinstance(e, dict) and e.get("tag") == tag), None)


def _is_number(value: Any) -> bool:
    """A finite JSON number (an integer past float's range is not one: it would print as inf)."""
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False
