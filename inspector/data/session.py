"""Native session format: read, validate, write atomically.

Layout (every array in dataset units: arm degrees or -100..100 as ``session.json`` says, gripper
0..100)::

    sessions/<session>/
      session.json            schema, name, robot, units, joint_names, gt_source, model
      rollouts/<tag>/
        rollout.json          kind, episode_index, start_frame, prompt, fps, horizon,
                              executed_per_chunk, frames_per_chunk, views, gt {...}
        actions.npy           (n_chunks, horizon, 6) predicted chunks; absent for a video-only
                              rollout (rollout.json then says ``n_chunks``)
        states.npy            optional (n_chunks + 1, 6) state before each chunk
        video/<view>.mp4      imagined frames, H.264
        gt/actions.npy        optional (T, 6) GT joints for steps start_frame .. start_frame+T-1
        gt/video/<view>.mp4   optional; frame i shows the real scene at imagined frame i's time
      annotations.json        flags and notes from the app, written atomically

Time: rollout step ``s`` is the s-th *executed* action (chunk ``s // executed_per_chunk``); it
happens at ``s / fps`` seconds after ``start_frame``. Imagined frame ``f`` of a chunk shows step
``f * executed_per_chunk / frames_per_chunk`` of that chunk.

A rollout without ``actions.npy`` is *video only* (a simulated evaluation run without recordings,
a policy server's predicted video): its rollout.json gives ``n_chunks`` (with ``horizon`` the steps
each chunk spans), it has imagined views and maybe GT views, and every joint metric of it is null.

Writing never leaves a half-written session: a new session is built in a temporary sibling
directory and renamed into place; a rollout added to an existing session is built in a temporary
directory under ``rollouts/`` and renamed; JSON files are replaced with ``os.replace``.

The format is read and written by role: what a session and a rollout are (``session_model``),
their arrays (``session_arrays``), reading (``session_reader``) and writing (``session_writer``).
This module is their one face (every caller imports from here); JSON reading and atomic writing
live in :mod:`inspector._files` and are named here too.
"""

from __future__ import annotations

from .._files import MAX_JSON_BYTES as MAX_JSON_BYTES
from .._files import check_json_size as check_json_size
from .._files import json_too_large as json_too_large
from .._files import parse_json as parse_json
from .._files import parse_json_text as parse_json_text
from .._files import read_json as read_json
from .._files import read_json_bytes as read_json_bytes
from .._files import read_json_object as read_json_object
from .._files import write_bytes_atomic as write_bytes_atomic
from .._files import write_json_atomic as write_json_atomic
from .session_arrays import ABSURD_VALUE as ABSURD_VALUE
from .session_arrays import ArrayValue as ArrayValue
from .session_arrays import NoJoints as NoJoints
from .session_arrays import NpyFile as NpyFile
from .session_arrays import check_values as check_values
from .session_arrays import load_array as load_array
from .session_model import _TAG as _TAG
from .session_model import _VIEW as _VIEW
from .session_model import ACTIONS_FILE as ACTIONS_FILE
from .session_model import ANNOTATIONS_FILE as ANNOTATIONS_FILE
from .session_model import CHAINED_KINDS as CHAINED_KINDS
from .session_model import GT_DIR as GT_DIR
from .session_model import KINDS as KINDS
from .session_model import LATENTS_FILE as LATENTS_FILE
from .session_model import MAX_FPS as MAX_FPS
from .session_model import MAX_VIDEO_ONLY_STEPS as MAX_VIDEO_ONLY_STEPS
from .session_model import MIN_FPS as MIN_FPS
from .session_model import OUTCOMES_FILE as OUTCOMES_FILE
from .session_model import OUTCOMES_SIDECAR_SUFFIX as OUTCOMES_SIDECAR_SUFFIX
from .session_model import ROLLOUT_FILE as ROLLOUT_FILE
from .session_model import ROLLOUTS_DIR as ROLLOUTS_DIR
from .session_model import SCHEMA as SCHEMA
from .session_model import SESSION_FILE as SESSION_FILE
from .session_model import STATES_FILE as STATES_FILE
from .session_model import VIDEO_DIR as VIDEO_DIR
from .session_model import Rollout as Rollout
from .session_model import RolloutKind as RolloutKind
from .session_model import Session as Session
from .session_model import fps_problem as fps_problem
from .session_model import is_rollout as is_rollout
from .session_model import is_session as is_session
from .session_reader import load_rollout as load_rollout
from .session_reader import load_session_rollout as load_session_rollout
from .session_reader import open_session as open_session
from .session_reader import read_session as read_session
from .session_reader import read_session_with_gt as read_session_with_gt
from .session_reader import rollout_dirs as rollout_dirs
from .session_writer import SessionWriter as SessionWriter
from .session_writer import check_apart as check_apart
from .session_writer import check_replaceable as check_replaceable
from .session_writer import make_staging_dir as make_staging_dir

__all__ = [
    "ABSURD_VALUE", "ACTIONS_FILE", "ANNOTATIONS_FILE", "ArrayValue", "CHAINED_KINDS", "GT_DIR", "KINDS",
    "LATENTS_FILE", "MAX_FPS", "MAX_JSON_BYTES", "MAX_VIDEO_ONLY_STEPS", "MIN_FPS", "NoJoints", "NpyFile",
    "OUTCOMES_FILE", "OUTCOMES_SIDECAR_SUFFIX", "ROLLOUTS_DIR", "ROLLOUT_FILE", "Rollout", "RolloutKind",
    "SCHEMA", "SESSION_FILE", "STATES_FILE", "Session", "SessionWriter", "VIDEO_DIR", "check_apart",
    "check_json_size", "check_replaceable", "check_values", "fps_problem", "is_rollout", "is_session",
    "json_too_large", "load_array", "load_rollout", "load_session_rollout", "make_staging_dir",
    "open_session", "parse_json", "parse_json_text", "read_json", "read_json_bytes", "read_json_object",
    "read_session", "read_session_with_gt", "rollout_dirs", "write_bytes_atomic", "write_json_atomic",
]
