"""Reading a native session: ``session.json`` and each rollout directory, validated, every
failure an :class:`InspectorError` naming the file and the field (the layout: :mod:`.session`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from .._files import read_json_object
from ..errors import InspectorError, require
from ..schema import shown, whole_number
from ..units import JOINT_NAMES, Units, parse_units
from .session_arrays import ArrayValue, NoJoints, NpyFile
from .session_model import (
    _VIEW,
    ACTIONS_FILE,
    GT_DIR,
    KINDS,
    LATENTS_FILE,
    MAX_VIDEO_ONLY_STEPS,
    ROLLOUT_FILE,
    ROLLOUTS_DIR,
    SCHEMA,
    SESSION_FILE,
    STATES_FILE,
    VIDEO_DIR,
    Rollout,
    Session,
    fps_problem,
)


def open_session(root: str | Path, check: Callable[[Path], None] | None = None, lazy: bool = False) -> Session:
    """Read ``session.json`` and every rollout under ``rollouts/`` (bad ones go to ``errors``).

    Args:
        root: the session directory.
        check: called with ``session.json`` and with each rollout directory before it is read;
            an :class:`InspectorError` it raises refuses the session (for ``session.json``) or
            that rollout (it goes to ``errors``). The app uses it to refuse symbolic links that
            lead outside the served roots (``inspector.data.sources.check_confined``).
        lazy: read the rollouts' arrays on first use (see :func:`load_rollout`).

    Raises:
        InspectorError: ``session.json`` itself is missing or invalid (or refused by ``check``).
    """
    session = read_session(root, check)
    for child in rollout_dirs(session.root):
        try:
            if check is not None:
                check(child)
            rollout = load_rollout(child, session.units, lazy=lazy)
            rollout.session = session
            session.rollouts[child.name] = rollout
        except InspectorError as exc:
            session.errors[child.name] = exc
    return session


def read_session_with_gt(session_root: str | Path, dataset: str | None, cameras_file: str | None = None,
                         outcomes_file: str | None = None) -> Session:
    """A session as a worker reads it (``session.json`` alone), its GT replaced by ``dataset``
    (``--dataset``) when given, its cameras and outcomes read from ``cameras_file`` and
    ``outcomes_file`` when given (a raw directory's sidecars: its temporary import holds neither)."""
    session = read_session(Path(session_root))
    if dataset is not None:
        session.gt_source["dataset"] = dataset
    if cameras_file is not None:
        session.cameras_file = Path(cameras_file)
    if outcomes_file is not None:
        session.outcomes_file = Path(outcomes_file)
    return session


def load_session_rollout(session: Session, tag: str) -> Rollout:
    """The rollout ``tag`` of ``session`` (from :func:`read_session_with_gt`), read and validated."""
    rollout = load_rollout(session.root / ROLLOUTS_DIR / tag, session.units)
    rollout.session = session
    return rollout


def rollout_dirs(root: Path) -> list[Path]:
    """The rollout directories of a session, by name (write-in-progress directories skipped)."""
    rollouts_dir = root / ROLLOUTS_DIR
    require(not rollouts_dir.exists() or rollouts_dir.is_dir(), rollouts_dir, "expected a directory")
    if not rollouts_dir.is_dir():
        return []
    # dot-directories are temporary directories of a write in progress
    return [c for c in sorted(rollouts_dir.iterdir()) if not c.name.startswith(".") and c.is_dir()]


def read_session(root: str | Path, check: Callable[[Path], None] | None = None) -> Session:
    """``session.json`` alone, validated: a :class:`Session` with no rollouts read.

    Raises:
        InspectorError: ``session.json`` is missing or invalid (or refused by ``check``).
    """
    root = Path(root)
    meta_path = root / SESSION_FILE
    if check is not None:
        check(meta_path)
    meta = read_json_object(meta_path)
    schema = meta.get("schema")
    require(schema == SCHEMA, meta_path, f"schema: expected {SCHEMA!r}, found {schema!r}")
    try:
        units = parse_units(meta.get("units", {}), "units")
    except ValueError as exc:
        raise InspectorError(meta_path, str(exc)) from None
    joint_names = meta.get("joint_names", list(JOINT_NAMES))
    require(joint_names == list(JOINT_NAMES), meta_path,
            f"joint_names: expected {list(JOINT_NAMES)}, found {joint_names}")
    robot = meta.get("robot", "so101")
    require(robot == "so101", meta_path, f"robot: only 'so101' is supported, found {robot!r}")
    for key in ("gt_source", "model"):
        require(isinstance(meta.get(key, {}), dict), meta_path, f"{key}: expected an object")
    dataset = meta.get("gt_source", {}).get("dataset")
    require(dataset is None or (isinstance(dataset, str) and "\x00" not in dataset), meta_path,
            f"gt_source.dataset: expected a path string, found {dataset!r}")
    return Session(
        root=root,
        name=str(meta.get("name", root.name)),
        robot=robot,
        units=units,
        joint_names=joint_names,
        gt_source=dict(meta.get("gt_source", {})),
        model=dict(meta.get("model", {})),
    )


def load_rollout(root: str | Path, units: Units | None = None, lazy: bool = False) -> Rollout:
    """Read and validate one rollout directory.

    Args:
        root: ``rollouts/<tag>``.
        units: the session's units (default: read the parent session, else degrees).
        lazy: check the arrays' shapes now but read their values on first use (a bad value then
            raises there); by default they are read and checked now.

    Raises:
        InspectorError: naming the file and the field at fault.
    """
    root = Path(root)
    meta_path = root / ROLLOUT_FILE
    meta = read_json_object(meta_path)
    if units is None:
        parent = root.parent.parent / SESSION_FILE
        units = Units()
        if parent.is_file():
            try:
                units = parse_units(read_json_object(parent).get("units", {}), "units")
            except ValueError as exc:
                raise InspectorError(parent, str(exc)) from None

    def get(key: str, kind: type | tuple[type, ...], default: Any = ...) -> Any:
        if key not in meta:
            require(default is not ..., meta_path, f"missing field {key!r}")
            return default
        value = meta[key]
        ok = isinstance(value, kind) and not (isinstance(value, bool) and bool not in _as_tuple(kind))
        require(ok, meta_path, f"{key}: expected {_type_names(kind)}, found {shown(value)}")
        return value

    kind = get("kind", str)
    require(kind in KINDS, meta_path, f"kind: expected one of {list(KINDS)}, found {kind!r}")
    horizon = get("horizon", int, 24)
    executed = get("executed_per_chunk", int, 9)
    frames_per_chunk = get("frames_per_chunk", int, 9)
    try:
        fps = float(get("fps", (int, float), 30))
    except OverflowError:  # an integer past float range
        raise InspectorError(meta_path, f"fps: must be a finite number, found {meta['fps']}") from None
    start_frame = get("start_frame", int, 0)
    episode_index = get("episode_index", (int, type(None)), None)
    for name, value in (("horizon", horizon), ("executed_per_chunk", executed),
                        ("frames_per_chunk", frames_per_chunk)):
        require(value >= 1, meta_path, f"{name}: must be >= 1, found {value}")
    require(executed <= horizon, meta_path,
            f"executed_per_chunk: {executed} exceeds horizon {horizon}")
    problem = fps_problem(fps)
    require(problem is None, meta_path, f"fps: {problem}")
    require(start_frame >= 0, meta_path, f"start_frame: must be >= 0, found {start_frame}")
    require(episode_index is None or episode_index >= 0, meta_path,
            f"episode_index: must be >= 0, found {episode_index}")
    views = get("views", list, [])
    require(all(isinstance(v, str) and _VIEW.match(v) for v in views), meta_path,
            f"views: expected names like 'front', found {views}")
    require(len(set(views)) == len(views), meta_path, f"views: listed twice in {views}")
    gt = get("gt", dict, {})
    gt_views = gt.get("views", [])
    require(isinstance(gt_views, list) and all(isinstance(v, str) and _VIEW.match(v) for v in gt_views),
            meta_path, f"gt.views: expected names like 'front', found {gt_views}")
    require(len(set(gt_views)) == len(gt_views), meta_path, f"gt.views: listed twice in {gt_views}")
    gt_len = gt.get("episode_length")
    require(gt_len is None or (isinstance(gt_len, int) and not isinstance(gt_len, bool) and gt_len > 0),
            meta_path, f"gt.episode_length: expected a positive integer, found {gt_len!r}")
    for name, value, least in (("horizon", horizon, 1), ("executed_per_chunk", executed, 1),
                               ("frames_per_chunk", frames_per_chunk, 1), ("start_frame", start_frame, 0),
                               ("episode_index", episode_index, 0), ("gt.episode_length", gt_len, 1)):
        if value is not None:  # below the least is said above; this bounds them from above
            whole_number(value, meta_path, name, minimum=least)

    arrays: dict[str, NpyFile | ArrayValue] = {}
    if not (root / ACTIONS_FILE).exists() and "n_chunks" in meta:  # video only
        n_video_chunks = whole_number(get("n_chunks", int), meta_path, "n_chunks", minimum=1)
        require(n_video_chunks * horizon <= MAX_VIDEO_ONLY_STEPS, meta_path,
                f"n_chunks: {n_video_chunks} chunks of {horizon} steps: more than the "
                f"{MAX_VIDEO_ONLY_STEPS:,} steps a video-only rollout may run")
        arrays["actions"] = NoJoints((n_video_chunks, horizon, len(JOINT_NAMES)))
    else:
        arrays["actions"] = NpyFile(root / ACTIONS_FILE, ("n_chunks", horizon, len(JOINT_NAMES)))
    n_chunks = arrays["actions"].shape[0]
    require(n_chunks >= 1, root / ACTIONS_FILE, "no chunks (shape[0] == 0)")
    if kind == "single_chunk":
        require(n_chunks == 1, root / ACTIONS_FILE, f"single_chunk rollout: expected 1 chunk, found {n_chunks}")
    if (root / STATES_FILE).exists():
        arrays["states"] = NpyFile(root / STATES_FILE, (n_chunks + 1, len(JOINT_NAMES)))
    if (root / LATENTS_FILE).exists():
        arrays["latents"] = NpyFile(root / LATENTS_FILE, ("n", "D"))
        require(arrays["latents"].shape[0] >= 1, root / LATENTS_FILE, "no latent vectors (shape[0] == 0)")
    if (root / GT_DIR / ACTIONS_FILE).exists():
        arrays["gt_actions"] = NpyFile(root / GT_DIR / ACTIONS_FILE, ("T", len(JOINT_NAMES)))
        require(arrays["gt_actions"].shape[0] >= 1, root / GT_DIR / ACTIONS_FILE, "no GT steps (shape[0] == 0)")
    if not lazy:
        for f in arrays.values():
            f.load()
    for view in views:
        require((root / VIDEO_DIR / f"{view}.mp4").is_file(), root / VIDEO_DIR / f"{view}.mp4",
                f"imagined video for view {view!r} not found")
    for view in gt_views:
        require((root / GT_DIR / VIDEO_DIR / f"{view}.mp4").is_file(),
                root / GT_DIR / VIDEO_DIR / f"{view}.mp4", f"GT video for view {view!r} not found")
    prompt = get("prompt", str, "")
    extra = get("extra", dict, {})
    return Rollout(
        root=root, tag=root.name, kind=kind, prompt=prompt, episode_index=episode_index,
        start_frame=start_frame, fps=fps, horizon=horizon, executed_per_chunk=executed,
        frames_per_chunk=frames_per_chunk, views=list(views), units=units,
        actions_shape=arrays["actions"].shape, gt_views=list(gt_views), gt_episode_length=gt_len,
        extra=extra, _arrays=arrays,
    )


def _as_tuple(kind: type | tuple[type, ...]) -> tuple[type, ...]:
    return kind if isinstance(kind, tuple) else (kind,)


def _type_names(kind: type | tuple[type, ...]) -> str:
    names = {"NoneType": "null", "str": "a string", "int": "an integer", "float": "a number",
             "list": "a list", "dict": "an object"}
    return " or ".join(names.get(k.__name__, k.__name__) for k in _as_tuple(kind))

