"""What the inspector reads and writes: native sessions (``session``), LeRobot datasets
(``lerobot_dataset``, written by ``lerobot_writer``), a dataset episode as a rollout
(``episodes``), GT resolution (``ground_truth``), video streaming (``video``), other labs' outputs
(``importers``), what a command-line PATH means (``sources``) and ``inspector info`` (``info``).

Every module, one line each, is on the map in docs/development.md ("Layout of the code"),
which tests/test_layout.py checks against the package.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "Rollout": ".session",
    "Session": ".session",
    "SessionWriter": ".session",
    "open_session": ".session",
    "read_session": ".session",
    "load_rollout": ".session",
    "LeRobotDataset": ".lerobot_dataset",
    "open_dataset": ".lerobot_dataset",
    "find_dataset": ".lerobot_dataset",
    "is_lerobot_dataset": ".lerobot_dataset",
    "dataset_name": ".lerobot_dataset",
    "EpisodeData": ".lerobot_writer",
    "write_lerobot_dataset": ".lerobot_writer",
    "EpisodeRef": ".episodes",
    "episode_refs": ".episodes",
    "episode_rollout": ".episodes",
    "GroundTruth": ".ground_truth",
    "resolve_ground_truth": ".ground_truth",
    "VideoClip": ".video",
    "probe": ".video",
    "encode_h264": ".video",
    "Sources": ".sources",
    "open_sources": ".sources",
    "describe": ".info",
    "format_info": ".info",
})

if TYPE_CHECKING:
    from .episodes import EpisodeRef as EpisodeRef
    from .episodes import episode_refs as episode_refs
    from .episodes import episode_rollout as episode_rollout
    from .ground_truth import GroundTruth as GroundTruth
    from .ground_truth import resolve_ground_truth as resolve_ground_truth
    from .info import describe as describe
    from .info import format_info as format_info
    from .lerobot_dataset import LeRobotDataset as LeRobotDataset
    from .lerobot_dataset import dataset_name as dataset_name
    from .lerobot_dataset import find_dataset as find_dataset
    from .lerobot_dataset import is_lerobot_dataset as is_lerobot_dataset
    from .lerobot_dataset import open_dataset as open_dataset
    from .lerobot_writer import EpisodeData as EpisodeData
    from .lerobot_writer import write_lerobot_dataset as write_lerobot_dataset
    from .session import Rollout as Rollout
    from .session import Session as Session
    from .session import SessionWriter as SessionWriter
    from .session import load_rollout as load_rollout
    from .session import open_session as open_session
    from .session import read_session as read_session
    from .sources import Sources as Sources
    from .sources import open_sources as open_sources
    from .video import VideoClip as VideoClip
    from .video import encode_h264 as encode_h264
    from .video import probe as probe
