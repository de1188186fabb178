"""What several importers share: rollout tags made from file and directory names, the check of
``--episode`` against a GT dataset, and DreamZero-SO101's 2x2 video mosaic."""

from __future__ import annotations

import hashlib
import re
import unicodedata

from ...errors import InspectorError
from ..lerobot_dataset import LeRobotDataset, dataset_name

MOSAIC_VIEWS = (("front", 0, 0), ("top", 0, 1), ("gripper", 1, 0))  # (view, row, col) of the 2x2
MAX_TAG_CHARS = 128


def missing_episode(ds: LeRobotDataset, index: int) -> str:
    """Why a rollout naming episode ``index`` of ``ds`` has no GT joints from it."""
    return f"dataset {dataset_name(ds)} has no episode {index} (episodes {ds.describe_episodes()}): no GT from it"


def check_episode_flag(ds: LeRobotDataset | None, episode: int | None) -> None:
    """Refuse ``--episode N`` that ``ds`` lacks (an episode named by a rollout's own files is a
    warning instead: that rollout is shown without GT from the dataset)."""
    if ds is not None and episode is not None and episode not in ds.episode_indexes():
        raise InspectorError(ds.root, f"episode {episode} is out of range; available: {ds.describe_episodes()} "
                                      "(--episode)")


def tag_from_name(name: str) -> str:
    """A valid tag (ASCII letters, digits, ``_.-``, 1-128 characters) made from a directory name:
    accents dropped (``épisode`` -> ``episode``), other characters -> ``_``, a name too long cut
    and ended with a hash of the whole name (so two long names stay apart)."""
    ascii_name = unicodedata.normalize("NFKD", name).encode("ascii", "ignore").decode("ascii")
    tag = re.sub(r"[^A-Za-z0-9_.-]+", "_", ascii_name).lstrip("._-").rstrip("_")
    if len(tag) > MAX_TAG_CHARS or not tag:  # too long, or nothing ASCII in it
        digest = hashlib.sha1(name.encode("utf-8", "surrogateescape")).hexdigest()[:8]
        tag = join_tag(tag, digest)
    return tag


def join_tag(head: str, tail: str) -> str:
    """``head_tail`` within the tag length, cutting ``head``."""
    head = head[: MAX_TAG_CHARS - len(tail) - 1].rstrip("._-")
    return f"{head}_{tail}" if head else tail
