"""Writing a native session atomically: a new session is built in a temporary sibling directory
and renamed into place; a rollout added to an existing session is built in a temporary directory
under ``rollouts/``, read back and renamed; nothing a user had at the destination is replaced
unless it is a session (or rollout) and ``overwrite`` says so (the layout: :mod:`.session`)."""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .._files import mkdtemp_sibling, short_name, write_json_atomic
from ..errors import InspectorError
from ..units import JOINT_NAMES, Units
from .session_model import (
    _TAG,
    ACTIONS_FILE,
    GT_DIR,
    LATENTS_FILE,
    ROLLOUT_FILE,
    ROLLOUTS_DIR,
    SCHEMA,
    SESSION_FILE,
    STATES_FILE,
    VIDEO_DIR,
    RolloutKind,
)
from .session_reader import load_rollout, open_session
from .video import VideoClip, encode_h264, probe


def make_staging_dir(dest: Path) -> Path:
    """A fresh hidden sibling of ``dest`` to build it in (``.<name>.<random>.partial``), with the
    mode ``mkdir`` would give (``mkdtemp``'s 0700 would stick to the directory once renamed)."""
    return mkdtemp_sibling(dest)


def check_replaceable(dest: Path, overwrite: bool, kind: str, marker: str) -> bool:
    """Decide what a write may do at ``dest``, the one rule for sessions and rollouts.

    Free to write: ``dest`` does not exist, or is an empty directory. With ``overwrite``, also
    a directory that holds ``marker`` (``session.json`` / ``rollout.json``). Anything else (a
    file, a symbolic link, a directory that is not a ``kind``) is the user's and is never
    replaced.

    Returns:
        True when ``dest`` holds a ``kind`` that the write will replace.

    Raises:
        InspectorError: ``dest`` may not be replaced.
    """
    if not os.path.lexists(dest):
        return False
    if dest.is_symlink() or not dest.is_dir():
        what = "a symbolic link" if dest.is_symlink() else "a file"
        raise InspectorError(dest, f"exists and is {what}, not a {kind}; refusing to replace it")
    if not any(dest.iterdir()):
        return False
    if not overwrite:
        raise InspectorError(dest, "already exists (pass overwrite=True / --overwrite to replace it)")
    if not (dest / marker).is_file():
        raise InspectorError(dest, f"is not a {kind} (no {marker}); --overwrite replaces only a {kind}, "
                                   "refusing to delete this directory")
    return True


def check_apart(dest: str | Path, source: str | Path, what: str = "the source") -> None:
    """Refuse to write a session at ``dest`` that overlaps what it is made from: ``dest`` is
    ``source``, holds it, or lies inside it, read through symbolic links (and bind mounts: each
    directory is compared by its device and inode too). Replacing such a session
    (``--overwrite``) would delete its own input; writing one inside its input changes it.
    Nothing is written or read but the two paths' metadata.

    Args:
        what: how the error names ``source`` (``the source``, ``the GT dataset``).

    Raises:
        InspectorError: naming ``dest``, and ``source`` in its text.
    """
    dest, source = Path(os.path.expanduser(dest)), Path(os.path.expanduser(source))
    relation = _overlap(dest, source)
    if relation is None:
        return
    why = {"same": f"is {what} {source} itself, which the session would replace",
           "holds": f"holds {what} {source}, which replacing the session would delete",
           "inside": f"lies inside {what} {source}, which the session would be written into"}[relation]
    links = [f"{p} resolves to {os.path.realpath(p)}" for p in (dest, source)
             if os.path.realpath(p) != os.path.abspath(p)]
    raise InspectorError(dest, why + (f" ({'; '.join(links)})" if links else "") + "; write the session elsewhere")


def _overlap(a: Path, b: Path) -> str | None:
    """How ``a`` stands to ``b``: ``same``, ``holds`` (b lies under a), ``inside`` (a lies under
    b), or None. Paths are resolved; existing directories also compare by (device, inode)."""
    ra, rb = a.resolve(), b.resolve()
    if ra == rb:
        return "same"
    if rb.is_relative_to(ra):
        return "holds"
    if ra.is_relative_to(rb):
        return "inside"

    def identity(p: Path) -> tuple[int, int] | None:
        try:
            st = p.stat()
        except OSError:
            return None
        return st.st_dev, st.st_ino

    ia, ib = identity(ra), identity(rb)
    if ia is not None and ia == ib:
        return "same"
    if ia is not None and any(identity(p) == ia for p in rb.parents):
        return "holds"
    if ib is not None and any(identity(p) == ib for p in ra.parents):
        return "inside"
    return None


def _replace_dir(staged: Path, dest: Path, overwrite: bool, kind: str, marker: str) -> None:
    """Move a complete staged directory to ``dest``; an old ``dest`` goes only once the new is in.

    Raises:
        InspectorError: ``dest`` may not be replaced (:func:`check_replaceable`), or another
            write took the place meanwhile. ``staged`` is left for the caller to remove.
    """
    if check_replaceable(dest, overwrite, kind, marker):
        trash = dest.with_name(f".{short_name(dest.name)}.old-{uuid.uuid4().hex[:8]}")
        os.replace(dest, trash)
        try:
            os.replace(staged, dest)
        except OSError:
            with contextlib.suppress(OSError):
                os.replace(trash, dest)  # put the old one back
            raise InspectorError(dest, f"another write replaced this {kind} at the same time; "
                                       "this one was dropped") from None
        shutil.rmtree(trash, ignore_errors=True)
        return
    try:
        os.replace(staged, dest)  # onto nothing, or onto an empty directory
    except OSError as exc:
        if exc.errno in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.EISDIR):
            raise InspectorError(dest, f"appeared while this {kind} was written (another write to "
                                       "the same place?); this one was dropped") from None
        raise


class SessionWriter:
    """Writes a session. What an evaluation script calls.

    Usage::

        from inspector.data.session import SessionWriter

        with SessionWriter.create("sessions/my_eval", name="my eval",
                                  model={"name": "my-wam", "checkpoint": "step-72000"},
                                  dataset="~/.cache/huggingface/lerobot/me/so101_pick") as session:
            session.add_rollout("ep000", kind="autoregressive", actions=chunks,   # (60, 24, 6)
                                episode_index=0, start_frame=0, prompt="Pick the red cube",
                                videos={"front": frames})                          # (540, H, W, 3)

    A new session appears at its path only when the ``with`` block ends without error.
    """

    def __init__(self, root: Path, final: Path | None, units: Units, overwrite: bool = False):
        self.root = root  # where files are written now
        self._final = final  # where a new session lands on commit (None: appending in place)
        self.units = units
        self._overwrite = overwrite
        self.tags: list[str] = []

    @classmethod
    def create(cls, dest: str | Path, *, name: str | None = None, units: Units = Units(),
               model: Mapping[str, Any] | None = None, dataset: str | Path | None = None,
               repo_id: str | None = None, overwrite: bool = False) -> SessionWriter:
        """Start a new session at ``dest`` (staged in a temporary sibling until committed)."""
        dest = Path(dest)
        check_replaceable(dest, overwrite, "session", SESSION_FILE)  # refuse before any work
        dest.parent.mkdir(parents=True, exist_ok=True)
        staged = make_staging_dir(dest)
        gt_source: dict[str, Any] = {}
        if dataset is not None:
            gt_source["dataset"] = str(dataset)
        if repo_id is not None:
            gt_source["repo_id"] = repo_id
        try:
            write_json_atomic(staged / SESSION_FILE, {
                "schema": SCHEMA,
                "name": name or dest.name,
                "robot": "so101",
                "units": units.to_json(),
                "joint_names": list(JOINT_NAMES),
                "gt_source": gt_source,
                "model": dict(model or {}),
            })
            (staged / ROLLOUTS_DIR).mkdir()
        except BaseException:
            shutil.rmtree(staged, ignore_errors=True)
            raise
        return cls(staged, dest, units, overwrite)

    @classmethod
    def append(cls, root: str | Path) -> SessionWriter:
        """Add rollouts to an existing session; each rollout appears atomically."""
        session = open_session(root)
        return cls(Path(root), None, session.units)

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.abort()

    def commit(self) -> Path:
        """Move a new session into place. Returns its final path.

        A commit that fails (the place was taken meanwhile, a rename failed) drops the staged
        session: nothing is left behind but what was at the destination before.
        """
        if self._final is None:
            return self.root
        try:
            _replace_dir(self.root, self._final, self._overwrite, "session", SESSION_FILE)
        except BaseException:
            self.abort()
            raise
        self.root, self._final = self._final, None
        return self.root

    def abort(self) -> None:
        """Drop a new session that was not committed (nothing appears at its path)."""
        if self._final is not None:
            shutil.rmtree(self.root, ignore_errors=True)

    def add_rollout(
        self,
        tag: str,
        *,
        kind: RolloutKind,
        actions: npt.ArrayLike | None,
        prompt: str = "",
        episode_index: int | None = None,
        start_frame: int = 0,
        fps: float = 30.0,
        executed_per_chunk: int = 9,
        frames_per_chunk: int = 9,
        states: npt.ArrayLike | None = None,
        videos: Mapping[str, Any] | None = None,
        gt_actions: npt.ArrayLike | None = None,
        gt_videos: Mapping[str, Any] | None = None,
        gt_episode_length: int | None = None,
        extra: Mapping[str, Any] | None = None,
        latents: npt.ArrayLike | None = None,
        overwrite: bool = False,
        n_chunks: int | None = None,
        horizon: int | None = None,
    ) -> Path:
        """Write one rollout (validated by reading it back before it becomes visible).

        Args:
            tag: directory name, letters/digits/``_.-``.
            kind: ``"single_chunk"``, ``"autoregressive"`` or ``"open_loop_replay"``.
            actions: (n_chunks, horizon, 6) predicted chunks in the session's units, or None for
                a video-only rollout (then ``n_chunks`` and ``horizon`` give its length: chunks,
                and steps each chunk spans).
            states: optional (n_chunks + 1, 6) state before each chunk.
            videos: ``{view: frames (N, H, W, 3) uint8 | path to a video}``; paths are copied if
                already H.264, otherwise re-encoded.
            gt_actions: optional (T, 6) GT joints from ``start_frame`` on.
            gt_videos: optional ``{view: frames | path}``; frame i at imagined frame i's time.
            gt_episode_length: length of the real episode [frames], when known.
            extra: provenance and reference values to keep (JSON-serialisable).
            latents: optional (n, D) latent vectors, one per chunk (or sample), for the latent
                stability test (``latents.npy``).

        Returns:
            The rollout directory.
        """
        if not _TAG.match(tag):
            raise InspectorError(tag, "rollout tag must be 1-128 letters, digits or _.- (not starting with . _ -)")
        dest = self.root / ROLLOUTS_DIR / tag
        if tag in self.tags or (dest.exists() and not overwrite):
            raise InspectorError((self._final or self.root) / ROLLOUTS_DIR / tag,
                                 f"rollout {tag!r} already exists in this session")
        if actions is None:
            if n_chunks is None or horizon is None:
                raise InspectorError(tag, "a video-only rollout (actions=None) needs n_chunks and horizon")
            actions_arr = np.zeros((int(n_chunks), int(horizon), 0))
        else:
            actions_arr = np.asarray(actions, dtype=np.float64)
        staged = make_staging_dir(dest)
        try:
            if actions is not None:
                np.save(staged / ACTIONS_FILE, actions_arr)
            if states is not None:
                np.save(staged / STATES_FILE, np.asarray(states, dtype=np.float64))
            if latents is not None:
                np.save(staged / LATENTS_FILE, np.asarray(latents, dtype=np.float64).reshape(
                    len(np.asarray(latents)), -1))
            if gt_actions is not None:
                (staged / GT_DIR).mkdir()
                np.save(staged / GT_DIR / ACTIONS_FILE, np.asarray(gt_actions, dtype=np.float64))
            for view, src in (videos or {}).items():
                _write_video(staged / VIDEO_DIR / f"{view}.mp4", src, fps)
            for view, src in (gt_videos or {}).items():
                _write_video(staged / GT_DIR / VIDEO_DIR / f"{view}.mp4", src, fps)
            meta: dict[str, Any] = {
                "kind": kind,
                "prompt": prompt,
                "episode_index": episode_index,
                "start_frame": int(start_frame),
                "fps": float(fps),
                "horizon": int(actions_arr.shape[1]) if actions_arr.ndim == 3 else 0,
                "executed_per_chunk": int(executed_per_chunk),
                "frames_per_chunk": int(frames_per_chunk),
                "views": sorted(videos or {}),
                "gt": {"views": sorted(gt_videos or {}), "episode_length": gt_episode_length},
                "units": self.units.to_json(),
            }
            if actions is None:
                meta["n_chunks"] = int(actions_arr.shape[0])
            if extra:
                meta["extra"] = dict(extra)
            write_json_atomic(staged / ROLLOUT_FILE, meta)
            load_rollout(staged, self.units)  # validate before it becomes visible
            _replace_dir(staged, dest, overwrite, "rollout", ROLLOUT_FILE)
        except (InspectorError, OSError) as exc:  # bad data, or a write error (disk full, ...)
            shutil.rmtree(staged, ignore_errors=True)
            if isinstance(exc, InspectorError):
                file, what = exc.file, exc.what
            else:
                file, what = str(exc.filename or staged), exc.strerror or str(exc)
            # name the file where it would have been, not in the temporary directory that is gone
            final = (self._final or self.root) / ROLLOUTS_DIR / tag
            raise InspectorError(file.replace(str(staged), str(final)), what) from None
        except BaseException:
            shutil.rmtree(staged, ignore_errors=True)
            raise
        self.tags.append(tag)
        return dest


def _write_video(dest: Path, src: Any, fps: float) -> None:
    """An H.264 file is copied as it is; any other video, or frames, are encoded frame by frame."""
    if isinstance(src, (str, Path)):
        info = probe(src)
        dest.parent.mkdir(parents=True, exist_ok=True)
        if info.codec == "h264":
            shutil.copyfile(src, dest)
            return
        frames: Any = (rgb for _, rgb in VideoClip(Path(src)).iter_frames())
    else:
        frames = np.asarray(src)
        if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
            raise InspectorError(dest, f"video frames: expected (N, H, W, 3) uint8, found {frames.shape} {frames.dtype}")
    encode_h264(dest, frames, fps)
