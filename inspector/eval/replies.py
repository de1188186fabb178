"""An ``infer`` reply checked and turned into a (horizon, 6) chunk in dataset units.

Two forms are read: an array (N, 6) (or a map holding one under ``action``), and the SO-101
servers' map ``{"action.joint_position": (N, 5), "action.gripper_position": (N, 1)}``. The
values are the server's, in the dataset's units (a server is trained on them); nothing is
converted or clamped. Predicted frames, when the reply carries them under a key asked for, are
kept as imagined video.

A chunk has at most :data:`MAX_HORIZON` steps (DreamZero-SO101's have 24, pi0's 50, ACT's 100): a
server answering millions of rows would otherwise fill the disk and every later ``report``. Shapes
are checked before anything is converted, so a refused reply costs no copy.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ..data.session import ABSURD_VALUE
from ..units import JOINT_NAMES
from .client import SampleError

JOINT_ACTION_KEY = "action.joint_position"
GRIPPER_ACTION_KEY = "action.gripper_position"
ACTION_KEY = "action"
# Steps a chunk may have: far past any policy's horizon, and small enough that a session of
# thousands of samples stays a few MB per thousand.
MAX_HORIZON = 1000
# Predicted frames larger than this on a side are no model's imagination [px] (as image_resolution).
MAX_FRAME_SIDE = 8192


class ReplyError(SampleError):
    """A reply arrived but is not a usable chunk (the connection stays good)."""


@dataclass
class Chunk:
    """One validated reply.

    Attributes:
        actions: (horizon, 6) float64, :data:`JOINT_NAMES` order, dataset units.
        form: ``"array"`` or ``"map"``: how the server sent it.
        videos: view -> (T, H, W, 3) uint8 predicted frames.
    """

    actions: npt.NDArray[np.float64]
    form: str
    videos: dict[str, npt.NDArray[np.uint8]] = field(default_factory=dict)


def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"an array {tuple(value.shape)} {value.dtype}"
    if isinstance(value, dict):
        keys = sorted(str(k)[:40] for k in list(value)[:100])
        return f"a map with keys {keys[:8]}" + (f" and {len(value) - 8} more" if len(value) > 8 else "")
    return f"{type(value).__name__} {str(value)[:40]!r}"


def _numeric(value: Any, what: str) -> np.ndarray:
    """``value`` if it is a numeric array (as it is: nothing converted before its shape is checked)."""
    if not isinstance(value, np.ndarray) or value.dtype.kind not in "fiu":
        raise ReplyError(f"reply: {what}: expected a numeric array, found {_describe(value)}")
    return value


def _column(value: Any, what: str) -> np.ndarray:
    """A (N, 1) or (N,) gripper array as (N, 1)."""
    arr = _numeric(value, what)
    return arr[:, None] if arr.ndim == 1 else arr


def _steps(arr: np.ndarray, what: str) -> None:
    if arr.shape[0] > MAX_HORIZON:
        raise ReplyError(f"reply: {what}: {arr.shape[0]} steps, more than the {MAX_HORIZON} a chunk may have")


def chunk_from_reply(reply: Any, video_keys: Mapping[str, str]) -> Chunk:
    """The chunk in ``reply``, checked: 2-D, 6 values per step, at least one step, finite.

    Args:
        reply: the decoded reply.
        video_keys: reply key -> view name of predicted frames to keep (missing keys are fine).

    Raises:
        ReplyError: one line saying what is wrong.
    """
    if isinstance(reply, np.ndarray):
        actions, form = _numeric(reply, "action chunk"), "array"
    elif isinstance(reply, dict) and JOINT_ACTION_KEY in reply:
        if GRIPPER_ACTION_KEY not in reply:
            raise ReplyError(f"reply: {JOINT_ACTION_KEY} without {GRIPPER_ACTION_KEY}")
        joints = _numeric(reply[JOINT_ACTION_KEY], JOINT_ACTION_KEY)
        gripper = _column(reply[GRIPPER_ACTION_KEY], GRIPPER_ACTION_KEY)
        if joints.ndim != 2 or joints.shape[1] != len(JOINT_NAMES) - 1:
            raise ReplyError(f"reply: {JOINT_ACTION_KEY}: expected (N, {len(JOINT_NAMES) - 1}) arm joints, "
                             f"found shape {tuple(joints.shape)}")
        _steps(joints, JOINT_ACTION_KEY)
        if gripper.ndim != 2 or gripper.shape != (joints.shape[0], 1):
            raise ReplyError(f"reply: {GRIPPER_ACTION_KEY}: expected ({joints.shape[0]}, 1), "
                             f"found shape {tuple(gripper.shape)}")
        actions, form = np.concatenate([joints, gripper], axis=1, dtype=np.float64), "map"
    elif isinstance(reply, dict) and ACTION_KEY in reply:
        actions, form = _numeric(reply[ACTION_KEY], ACTION_KEY), "map"
    else:
        raise ReplyError(f"reply: expected an (N, 6) action chunk or a map with {JOINT_ACTION_KEY} and "
                         f"{GRIPPER_ACTION_KEY}, found {_describe(reply)}")
    if actions.ndim != 2 or actions.shape[1] != len(JOINT_NAMES):
        raise ReplyError(f"reply: expected (N, {len(JOINT_NAMES)}) joints per step (5 arm joints + gripper), "
                         f"found shape {tuple(actions.shape)}")
    if actions.shape[0] < 1:
        raise ReplyError("reply: an empty chunk (0 steps)")
    _steps(actions, "action chunk")
    actions = actions.astype(np.float64)
    bad = ~np.isfinite(actions) | (np.abs(actions) > ABSURD_VALUE)
    if bad.any():
        step, joint = (int(i) for i in np.argwhere(bad)[0])
        kind = "non-finite" if not np.isfinite(actions[step, joint]) else "absurd"
        raise ReplyError(f"reply: {kind} value {actions[step, joint]:g} at step {step}, joint {JOINT_NAMES[joint]}")
    videos = {}
    for key, view in video_keys.items():
        frames = reply.get(key) if isinstance(reply, dict) else None
        if frames is None:
            continue
        if not (isinstance(frames, np.ndarray) and frames.dtype == np.uint8 and frames.ndim == 4
                and frames.shape[-1] == 3 and frames.shape[0] >= 1
                and all(1 <= n <= MAX_FRAME_SIDE for n in frames.shape[1:3])):
            raise ReplyError(f"reply: {key}: expected predicted frames (T, H, W, 3) uint8, H and W in "
                             f"1..{MAX_FRAME_SIDE}, found {_describe(frames)}")
        videos[view] = frames
    return Chunk(actions, form, videos)
