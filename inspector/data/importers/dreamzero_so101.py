"""Import DreamZero-SO101 evaluation artefacts into a native session.

Source directories, found recursively under the path given::

    train_rollout/<tag>/            autoregressive ("DreamGen") rollout
      action_trace.npy              (n_chunks, 24, 6) every predicted chunk
      state_trace.npy               (n_chunks + 1, 6); state_trace[k+1] == action_trace[k][8]
      meta.json                     episode, prompt, episode_length, frames_per_step, ...
      rollout_<view>.mp4            imagined video, one frame per executed step
      gt_<view>.mp4                 the real episode's video from its first frame
    <any>/<tag>/                    single chunk
      meta.json                     actions_pred, actions_gt (24, 6), state_in | state, frame_in_ep
      pred_<view>.mp4 | predicted_video.mp4 (2x2 mosaic [front|top; gripper|black], 640x352)
      gt_<view>.mp4   | gt_future.mp4       (the front camera alone, 640x480 resized to 640x352:
                                             these samples have GT video of the front view only)

Values are the model's raw outputs (arm degrees, gripper 0..100) and are kept as they are:
joint-limit violations are findings, not something to clamp away. The metas' own metrics are
kept as the source's figures (``extra.reference_metrics``), with a note where one is not what its
name suggests (``extra.reference_notes``): a mosaic sample's ``video_psnr_db`` compared the whole
mosaic with the single front view.

A sample listed in ``aggregate.json`` / ``all_metas.json`` without a folder is a single-chunk
rollout without video (said in ``extra.source_notes``); where a folder and its entry disagree,
the folder's meta.json is used and the note says so. Each rollout's distribution (``extra.distribution``:
``zero-shot`` / ``training``) and dataset (``extra.dataset``) are set where the checkout says them;
the ``train_rollout/`` summary files' figures join ``extra.reference_metrics`` as ``<file>:<field>``
(see :mod:`.dreamzero_so101_summaries`).

A rollout's tag is its directory name made into a valid tag (ASCII letters, digits, ``_.-``, at
most 128 characters); the directory's own name is kept in ``extra.source.name``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InspectorError, require
from ...schema import whole_number
from ...units import JOINT_NAMES, Units
from ..lerobot_dataset import LeRobotDataset, find_dataset
from ..session import SessionWriter, check_apart, check_values, json_too_large, load_array, read_json_object
from ..video import decode
from .dreamzero_so101_summaries import INDEX_NAMES, SampleIndex, TrainSummaries, claims_index, differences, distribution_of, read_index, training_dataset
from .in_memory import InMemory, import_temporarily
from .shared import MOSAIC_VIEWS, check_episode_flag, join_tag, missing_episode, tag_from_name

PRED_MOSAIC = "predicted_video.mp4"
GT_FRONT_ONLY = "gt_future.mp4"  # beside a mosaic: the front camera alone, not a mosaic
MOSAIC_PSNR_NOTE = ("compared the whole 2x2 mosaic (front, top, gripper, black) with the front camera "
                    "alone; not a per-view PSNR")
ROLLOUT_VIEW_PREFIX = "rollout_"
REFERENCE_FIELDS = ("action_rmse_deg", "action_mse_deg2", "per_joint_rmse", "per_step_mse",
                    "video_psnr_db", "video_pixel_mse", "mean_drift_deg", "final_drift_deg")


@dataclass
class Listed:
    """A sample's entry ``i`` in an ``aggregate.json`` / ``all_metas.json``."""

    index: SampleIndex
    i: int


@dataclass
class SourceDir:
    path: Path  # a listed sample without a folder: where its folder would be
    kind: str  # "autoregressive" | "single_chunk" | "listed" (a sample only an index lists)
    listed: Listed | None = None  # its entry in an index (a folder's too, compared with its meta.json)
    error: InspectorError | None = None  # an index that could not be read


def find_sources(src: str | Path) -> list[SourceDir]:
    """Every DreamZero-SO101 rollout directory at or under ``src``, and every sample an
    ``aggregate.json`` / ``all_metas.json`` there lists without a folder, sorted by path."""
    src = Path(src)
    if not src.exists():
        raise InspectorError(src, "not found")
    candidates = [src] if src.is_dir() else []
    candidates += sorted(p for p in src.rglob("*") if p.is_dir()) if src.is_dir() else []
    found = [s for s in (_classify(p) for p in candidates) if s is not None]
    found += _listed_sources(candidates, found)
    if not found:
        raise InspectorError(src, "no DreamZero-SO101 rollout found (expected action_trace.npy + "
                                  "meta.json, meta.json with actions_pred/actions_gt, or aggregate.json)")
    return sorted(found, key=lambda s: s.path)


def _listed_sources(candidates: list[Path], found: list[SourceDir]) -> list[SourceDir]:
    """The entries of every index under the candidates: each joins its folder's source where
    that folder was found, else is a source of its own (an unreadable index: one with ``error``)."""
    folders = {s.path: s for s in found if s.kind == "single_chunk"}
    out = []
    for directory in candidates:
        for index_path in (directory / name for name in INDEX_NAMES):
            if not claims_index(index_path):
                continue
            try:
                index = read_index(index_path)
            except InspectorError as exc:
                out.append(SourceDir(index_path, "listed", error=exc))
                continue
            for i in range(len(index.entries)):
                tag = index.tag(i)
                folder = folders.get(directory / tag) if tag is not None else None
                if folder is not None and folder.listed is None:
                    folder.listed = Listed(index, i)
                else:
                    out.append(SourceDir(directory / (tag or f"sample{i}"), "listed", Listed(index, i)))
    return out


def _classify(path: Path) -> SourceDir | None:
    if (path / "action_trace.npy").is_file():
        return SourceDir(path, "autoregressive")
    meta = path / "meta.json"
    if meta.is_file():
        if json_too_large(meta):
            return SourceDir(path, "single_chunk")  # ours by name: the importer refuses its size
        try:
            data = json.loads(meta.read_text())
        except (ValueError, RecursionError):
            # looks like ours only by name: let the importer report it properly
            return SourceDir(path, "single_chunk")
        if isinstance(data, dict) and "actions_pred" in data:
            return SourceDir(path, "single_chunk")
    return None


def import_dreamzero(
    src: str | Path,
    dest: str | Path,
    *,
    dataset: str | Path | None = None,
    episode: int | None = None,
    overwrite: bool = False,
    log: Callable[[str], None] = print,
) -> Path:
    """Import every rollout under ``src`` into a new session at ``dest``.

    Args:
        src: a rollout directory or any parent of several.
        dest: the session directory to create (appears only when the import succeeded).
        dataset: optional LeRobot dataset holding the GT episode; its actions become the
            rollouts' GT joints.
        episode: episode index in ``dataset`` (default: each rollout's own ``episode``).
        log: receives one summary line per rollout.

    Returns:
        The session directory.
    """
    return _import(src, dest, dataset=dataset, episode=episode, overwrite=overwrite, log=log)[0]


def _import(src: str | Path, dest: str | Path, *, dataset: str | Path | None = None, episode: int | None = None,
            overwrite: bool = False, keep_going: bool = False, log: Callable[[str], None] = print,
            ) -> tuple[Path, dict[str, InspectorError]]:
    """:func:`import_dreamzero`, and with ``keep_going`` a bad sample of an index (or an index
    that cannot be read) is returned among the errors while the others are imported; a bad
    folder always stops the import."""
    sources = find_sources(src)
    src = Path(src)
    check_apart(dest, src)
    ds = None
    if dataset is not None:

        ds = LeRobotDataset(find_dataset(dataset))
        check_apart(dest, ds.root, "the GT dataset")
        check_episode_flag(ds, episode)
    checkout = Checkout(src, sources)
    units = ds.units if ds is not None else Units("degrees")
    errors: dict[str, InspectorError] = {}
    with SessionWriter.create(dest, name=Path(dest).name, units=units,
                              model={"name": "DreamZero-SO101"},
                              dataset=str(Path(ds.root).resolve()) if ds is not None else None,
                              overwrite=overwrite) as writer:
        used: set[str] = set()
        for source in sources:
            tag = unique_tag(source.path, src, used)
            try:
                args = checkout.rollout_args(source, tag)
            except InspectorError as exc:
                if not (keep_going and source.kind == "listed"):
                    raise
                errors[tag] = exc
                log(f"{tag}: error: {exc}")
                continue
            warning = _attach_dataset_gt(args, ds, episode, source.path) if ds is not None else None
            if warning is not None:
                args["extra"].setdefault("warnings", []).append(warning)
            writer.add_rollout(tag, **args)
            notes = [*args["extra"].get("source_notes", []), *([warning] if warning else [])]
            log(_summary(tag, args) + "".join(f"; warning: {w}" for w in notes))
    return Path(dest), errors


def load_in_memory(src: Path, dataset: str | Path | None = None) -> InMemory:
    """Import into a temporary session (for ``report``/``serve``/``export`` on a raw source dir);
    a bad sample of an ``aggregate.json`` / ``all_metas.json`` is left out and returned among the
    errors, the others are imported."""
    return import_temporarily(Path(src).resolve().name, lambda dest: _import(
        src, dest, dataset=dataset, log=lambda _: None, keep_going=True)[1])


class Checkout:
    """What the whole source tree says about each of its rollouts: the indexes beside the
    folders, the training dataset a zero-shot disclosure names, the summary files."""

    def __init__(self, root: Path, sources: list[SourceDir]) -> None:
        self.root = root.resolve()
        indexes = {id(s.listed.index): s.listed.index for s in sources if s.listed is not None}
        self.by_dir = {index.path.parent.resolve(): index for index in indexes.values()}
        self.training = training_dataset(list(indexes.values()))
        self.summaries = TrainSummaries(self.shown)

    def shown(self, path: Path) -> str:
        """``path`` as messages name it: from the source directory's own name on."""
        path = Path(path).resolve()
        return str(path.relative_to(self.root.parent)) if path.is_relative_to(self.root.parent) else str(path)

    def rollout_args(self, source: SourceDir, tag: str, cut_mosaic: bool = True) -> dict[str, Any]:
        """The :meth:`SessionWriter.add_rollout` arguments of one source, its notes, distribution
        and the repository's figures in ``extra`` (``cut_mosaic`` False: a mosaic's views are named,
        not cut, for ``inspector info``)."""
        if source.error is not None:
            raise source.error
        listed = source.listed
        # the index that lists the sample, else one beside its folder
        index = listed.index if listed is not None else self.by_dir.get(source.path.parent.resolve())
        if source.kind == "autoregressive":
            args = _autoregressive(source.path)
            figures, files, notes = self.summaries.figures(source.path, source.path.name)
            args["extra"]["reference_metrics"].update(figures)
            args["extra"]["source_notes"] = notes
            if files:
                args["extra"]["reference_sources"] = {"meta.json": str(source.path.resolve() / "meta.json"), **files}
        elif source.kind == "single_chunk":
            args = _single_chunk(source.path, index.context if index is not None else None, cut_mosaic)
            if index is not None and index.context:  # its episode, length or prompt may come from there
                args["extra"]["source"]["also_read"] = [str(index.path.resolve())]
            args["extra"]["source_notes"] = self._compare(source.path, listed) if listed is not None else []
        else:
            assert listed is not None
            args = self._listed(source, listed)
        if index is not None and index.figures:
            args["extra"]["reference_metrics"].update({f"{index.path.name}:{k}": v for k, v in index.figures.items()})
            args["extra"].setdefault("reference_sources", {})[index.path.name] = str(index.path.resolve())
        marked = distribution_of(source.path, tag, index, self.training, self.shown)
        args["extra"].update(marked)
        if marked:  # the app's card and the .rrd description show it
            args["extra"].setdefault("facts", []).append(
                ["distribution", f"{marked['distribution']} ({marked['distribution_source']})"])
        if not args["extra"]["source_notes"]:
            del args["extra"]["source_notes"]
        return args

    def _listed(self, source: SourceDir, listed: Listed) -> dict[str, Any]:
        """A sample only an index holds: its actions and GT from the entry, no video."""
        index, where = listed.index, listed.index.where(listed.i)
        try:
            meta = index.sample_meta(listed.i)
            args = _chunk_args(meta, index.path, None)
        except InspectorError as exc:
            raise InspectorError(index.path, f"{where}: {exc.what}") from None
        args["extra"]["source"].update(path=str(index.path.resolve()), name=source.path.name, entry=where)
        args["extra"]["source_notes"] = [f"no sample folder {self.shown(source.path)} with meta.json: shown without "
                                         f"video, its actions from {self.shown(index.path)} {where}"]
        args["extra"]["facts"] = [["video", f"none: the checkout has no folder for this sample; its actions "
                                            f"and GT are {self.shown(index.path)} {where}"]]
        return args

    def _compare(self, folder: Path, listed: Listed) -> list[str]:
        """What to say where a folder's meta.json and its index entry differ (the folder is used)."""
        index, where = listed.index, listed.index.where(listed.i)
        entry = index.entries[listed.i]
        named = f"{self.shown(index.path)} {where}"
        if not isinstance(entry, dict):
            return [f"its entry {named} is not an object: {self.shown(folder / 'meta.json')} is used"]
        differ = differences(read_json_object(folder / "meta.json"), entry)
        if differ:
            return [f"{self.shown(folder / 'meta.json')} and {named} differ in {', '.join(differ)}: "
                    f"the folder's meta.json is used"]
        return []


# ----------------------------------------------------------------------------------------------


def _autoregressive(path: Path) -> dict[str, Any]:
    meta_path = path / "meta.json"
    meta = read_json_object(meta_path)
    actions = load_array(path / "action_trace.npy", ("n_chunks", "horizon", len(JOINT_NAMES)))
    n_chunks, horizon, _ = actions.shape
    require(n_chunks >= 1, path / "action_trace.npy", "no chunks (shape[0] == 0)")
    states = None
    if (path / "state_trace.npy").exists():
        states = load_array(path / "state_trace.npy", (n_chunks + 1, len(JOINT_NAMES)))
    executed = _int_field(meta, "frames_per_step", meta_path, default=9)
    require(1 <= executed <= horizon, meta_path,
            f"frames_per_step: {executed} must lie in 1..{horizon} (the chunk horizon)")
    chained = None
    if states is not None:
        # each chunk starts where the previous one's last executed action left the arm
        chained = bool(np.allclose(states[1:], actions[:, executed - 1], atol=1e-6))
    views = _views(path, ROLLOUT_VIEW_PREFIX)
    gt_views = _views(path, "gt_")
    episode_length = _length_field(meta, meta_path)
    return dict(
        kind="autoregressive",
        actions=actions,
        states=states,
        prompt=_str_field(meta, "prompt", meta_path),
        episode_index=_int_field(meta, "episode", meta_path, default=None),
        start_frame=_int_field(meta, "start_frame", meta_path, default=0),
        executed_per_chunk=executed,
        frames_per_chunk=executed,
        videos={v: path / f"{ROLLOUT_VIEW_PREFIX}{v}.mp4" for v in views},
        gt_videos={v: path / f"gt_{v}.mp4" for v in gt_views},
        gt_episode_length=episode_length,
        extra=_extra(meta, path, chained_states=chained,
                     initial_state=meta.get("initial_state", states[0].tolist() if states is not None else None)),
    )


def _single_chunk(path: Path, context: dict[str, Any] | None = None, cut_mosaic: bool = True) -> dict[str, Any]:
    """A sample's folder; ``context``: what an index beside it says of all its samples (the
    episode, its length, the prompt), where its meta.json does not say."""
    meta_path = path / "meta.json"
    return _chunk_args({**(context or {}), **read_json_object(meta_path)}, meta_path, path, cut_mosaic)


def _chunk_args(meta: dict[str, Any], meta_path: Path, path: Path | None, cut_mosaic: bool = True) -> dict[str, Any]:
    """A single chunk from its meta (a folder's meta.json, or an index entry: ``path`` None, no
    video); errors name ``meta_path`` and the field."""
    pred = _matrix_field(meta, "actions_pred", meta_path)
    gt = _matrix_field(meta, "actions_gt", meta_path) if "actions_gt" in meta else None
    if gt is not None:
        require(gt.shape == pred.shape, meta_path,
                f"actions_gt: shape {gt.shape} differs from actions_pred {pred.shape}")
    state_in = meta.get("state_in", meta.get("state"))
    if path is None:  # an entry of an index: nothing else checks its state
        state_in = None if state_in is None else _vector_field(state_in, "state_in", meta_path).tolist()
    videos = _split_views(path, "pred_", PRED_MOSAIC, cut_mosaic) if path is not None else {}
    gt_views = _views(path, "gt_", GT_FRONT_ONLY) if path is not None else []
    gt_videos: dict[str, Any] = {v: path / f"gt_{v}.mp4" for v in gt_views} if path is not None else {}
    if path is not None and not gt_videos and (path / GT_FRONT_ONLY).is_file():
        gt_videos = {"front": path / GT_FRONT_ONLY}
    notes = {}
    if path is not None and (path / PRED_MOSAIC).is_file() and (path / GT_FRONT_ONLY).is_file() \
            and "video_psnr_db" in meta:
        notes["video_psnr_db"] = MOSAIC_PSNR_NOTE
    executed = min(9, pred.shape[0])
    frames = _int_field(meta, "predicted_frames", meta_path, default=9)
    require(frames >= 1, meta_path, f"predicted_frames: must be >= 1, found {frames}")
    return dict(
        kind="single_chunk",
        actions=pred[None],
        prompt=_str_field(meta, "prompt", meta_path),
        episode_index=_int_field(meta, "episode", meta_path, default=None),
        start_frame=_int_field(meta, "frame_in_ep", meta_path, default=0),
        executed_per_chunk=executed,
        frames_per_chunk=frames,
        gt_actions=gt,
        videos=videos,
        gt_videos=gt_videos,
        gt_episode_length=_length_field(meta, meta_path),
        extra=_extra(meta, path if path is not None else meta_path, initial_state=state_in,
                     reference_notes=notes or None),
    )


def _views(path: Path, prefix: str, mosaic_name: str = "") -> list[str]:
    """View names of ``<prefix><view>.mp4`` files (display/slow/full variants and mosaics are not views)."""
    views = []
    for f in sorted(path.glob(f"{prefix}*.mp4")):
        view = f.stem[len(prefix):]
        if view and "_" not in view and f.name != mosaic_name:
            views.append(view)
    return views


def _split_views(path: Path, prefix: str, mosaic_name: str, cut_mosaic: bool = True) -> dict[str, Any]:
    """Per-view clips: the ``<prefix><view>.mp4`` files, else the 2x2 mosaic cut into views
    (paths, or frames for the cut views; ``cut_mosaic`` False: the mosaic's path for each view)."""
    views = _views(path, prefix, mosaic_name)
    if views:
        return {v: path / f"{prefix}{v}.mp4" for v in views}
    mosaic = path / mosaic_name
    if not mosaic.is_file():
        return {}
    if not cut_mosaic:
        return {view: mosaic for view, _, _ in MOSAIC_VIEWS}
    frames, _ = decode(mosaic)
    h, w = frames.shape[1] // 2, frames.shape[2] // 2
    out = {}
    for view, row, col in MOSAIC_VIEWS:
        out[view] = frames[:, row * h:(row + 1) * h, col * w:(col + 1) * w]
    return out


def _attach_dataset_gt(args: dict[str, Any], ds: Any, episode: int | None, path: Path) -> str | None:
    """Take GT joints (and length) from the dataset episode the rollout started in; an episode
    the dataset lacks leaves the rollout as it is (its own GT, if any) and is returned as a warning."""
    index = episode if episode is not None else args["episode_index"]
    if index is None:
        raise InspectorError(path / "meta.json", "episode: not given; pass --episode N with --dataset")
    if index not in ds.episode_indexes():  # (--episode was checked up front)
        return missing_episode(ds, index)
    ep = ds.episode(index)
    start = args["start_frame"]
    require(start < ep.length, path / "meta.json",
            f"start frame {start} lies beyond episode {index} ({ep.length} frames)")
    args["episode_index"] = index
    args["gt_actions"] = ep.action[start:]
    args["gt_episode_length"] = ep.length
    return None


def _extra(meta: dict[str, Any], path: Path, **more: Any) -> dict[str, Any]:
    # the source's own figures: a non-finite or non-numeric one is no figure (strict JSON out)
    reference = {k: meta[k] for k in REFERENCE_FIELDS if k in meta and _is_figure(meta[k])}
    info = {k: meta[k] for k in ("training_task", "prompt_kind", "episode_length", "n_steps",
                                 "total_imagined_frames", "final_imagined_state") if k in meta}
    return {"source": {"format": "dreamzero_so101", "path": str(path.resolve()), "name": path.resolve().name,
                       **info},
            "reference_metrics": reference, **{k: v for k, v in more.items() if v is not None}}


def _str_field(meta: dict[str, Any], key: str, path: Path) -> str:
    value = meta.get(key, "")
    require(isinstance(value, str), path, f"{key}: expected a string, found {value!r}")
    return value


def _int_field(meta: dict[str, Any], key: str, path: Path, default: Any) -> Any:
    value = meta.get(key, default)
    return value if value is default else whole_number(value, path, key)


def _matrix_field(meta: dict[str, Any], key: str, path: Path) -> np.ndarray:
    require(key in meta, path, f"missing field {key!r}")
    try:
        arr = np.asarray(meta[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise InspectorError(path, f"{key}: expected a (horizon, 6) list of numbers") from None
    except OverflowError:  # an integer past float64's range (JSON integers have no limit)
        raise InspectorError(path, f"{key}: a number too large for a 64-bit float") from None
    require(arr.ndim == 2 and arr.shape[1] == len(JOINT_NAMES) and arr.shape[0] >= 1, path,
            f"{key}: expected shape (horizon, {len(JOINT_NAMES)}), found {arr.shape}")
    check_values(arr, path, f"{key}: ")
    return arr


def _vector_field(value: Any, key: str, path: Path) -> np.ndarray:
    """A joint vector (6 numbers) of an index entry, e.g. its ``state_in``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InspectorError(path, f"{key}: expected {len(JOINT_NAMES)} numbers") from None
    require(arr.shape == (len(JOINT_NAMES),), path, f"{key}: expected shape ({len(JOINT_NAMES)},), found {arr.shape}")
    check_values(arr, path, f"{key}: ")
    return arr


def _is_figure(value: Any) -> bool:
    """A finite number, or a list of them (per joint, per step)."""
    values = value if isinstance(value, list) else [value]
    try:
        return all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(float(v)) for v in values)
    except OverflowError:
        return False


def _length_field(meta: dict[str, Any], path: Path) -> int | None:
    """``episode_length``: absent/null, or a positive integer."""
    value = meta.get("episode_length")
    return None if value is None else whole_number(value, path, "episode_length", minimum=1)


def unique_tag(path: Path, root: Path, used: set[str]) -> str:
    """A valid rollout tag for a source directory, unique among ``used`` (which it joins)."""
    base = tag_from_name(path.name if path != root else root.resolve().name)
    tag, n = base, 2
    while tag in used:
        parent = tag_from_name(path.parent.name) if path.parent.name else ""
        tag = join_tag(parent, base) if n == 2 and parent else join_tag(base, str(n))
        n += 1
    used.add(tag)
    return tag


def _summary(tag: str, args: dict[str, Any]) -> str:
    actions = args["actions"]
    views = ",".join(sorted(args.get("videos") or {})) or "none"
    gt = "GT joints" if args.get("gt_actions") is not None else "no GT joints"
    rmse = ""
    if args.get("gt_actions") is not None and args["kind"] == "single_chunk":
        diff = actions[0] - args["gt_actions"][: actions.shape[1]]
        rmse = f", RMSE {np.sqrt(np.mean(diff ** 2)):.3f} deg"
    return (f"{tag}: {args['kind']}, {actions.shape[0]} chunk(s) x {actions.shape[1]} steps, "
            f"views {views}, {gt}{rmse}, prompt {args['prompt']!r}")
