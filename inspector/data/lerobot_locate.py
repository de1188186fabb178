"""Finding a LeRobot dataset on local disk: a directory, or an ``org/name`` repo id looked up where
LeRobot keeps datasets (``$HF_LEROBOT_HOME`` and its fallbacks, the order LeRobot resolves them in),
fetched from the Hub only when asked; and how a dataset is named in pickers and reports.

Apart from the reader because finding needs no dataset read: ``inspector info`` and the source
scan ask "is this a dataset?" of many directories, and a Hugging Face cache snapshot (every file a
symlink into ``blobs/``) is recognised here, once.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import sys
from pathlib import Path

from ..errors import InspectorError
from .hub import fetch_dataset
from .lerobot_format import CODEBASE_VERSION_KEY, INFO_PATH, _expand
from .lerobot_meta import LeRobotMetadata
from .session import json_too_large


def is_lerobot_dataset(path: str | Path) -> bool:
    """True when ``path/meta/info.json`` exists and names a ``codebase_version``."""
    info = _expand(path) / INFO_PATH
    if json_too_large(info):
        return True  # named like a dataset's: the reader refuses its size in one line
    try:
        return isinstance(obj := json.loads(info.read_text()), dict) and CODEBASE_VERSION_KEY in obj
    except (OSError, ValueError, RecursionError):
        return False


REPO_ID = re.compile(r"^[A-Za-z0-9][\w.-]*/[\w.-]+$")  # a Hugging Face repo id: org/name


def dataset_name(ds: LeRobotMetadata) -> str:
    """How a dataset is named in pickers and reports: ``org/name`` under a LeRobot home, else its
    directory's name."""
    root = ds.root.resolve()
    repo = hub_snapshot_repo(root)
    if repo is not None:  # datasets--org--name
        org, _, name = repo.name[len(HUB_REPO_PREFIX):].partition("--")
        return f"{org}/{name}" if name else org
    for home in lerobot_home_dirs():
        try:
            rel = root.relative_to(home.resolve())
        except (ValueError, OSError):
            continue
        if len(rel.parts) == 2:
            return "/".join(rel.parts)
    return root.name


# The Hugging Face hub cache (``huggingface_hub.snapshot_download``) keeps a dataset as
#   <hub>/datasets--<org>--<name>/snapshots/<revision>/...   every file a symlink into
#   <hub>/datasets--<org>--<name>/blobs/<hash>               the files' contents
HUB_REPO_PREFIX = "datasets--"
HUB_SNAPSHOTS_DIR = "snapshots"
HUB_BLOBS_DIR = "blobs"


def hub_snapshot_repo(root: Path) -> Path | None:
    """The hub cache repository directory (``datasets--<org>--<name>``) of a dataset that is one
    of its snapshots, else None."""
    snapshots = root.parent
    repo = snapshots.parent
    if snapshots.name == HUB_SNAPSHOTS_DIR and repo.name.startswith(HUB_REPO_PREFIX) and (repo / HUB_BLOBS_DIR).is_dir():
        return repo
    return None


def dataset_file_roots(root: Path) -> list[Path]:
    """The directories a dataset's files may resolve into: the dataset itself, and for a hub
    cache snapshot the ``blobs/`` directory its files are symlinks into (nothing else of the
    cache: not other repositories)."""
    repo = hub_snapshot_repo(root)
    return [root] if repo is None else [root, repo / HUB_BLOBS_DIR]


def lerobot_home_dirs() -> list[Path]:
    """Where LeRobot keeps datasets, most specific first (no duplicates).

    ``$HF_LEROBOT_HOME``, else ``$HF_HOME/lerobot``, else ``$XDG_CACHE_HOME/huggingface/lerobot``,
    else ``~/.cache/huggingface/lerobot`` -- the same order LeRobot resolves ``HF_LEROBOT_HOME``.
    """
    dirs: list[Path] = []
    if os.environ.get("HF_LEROBOT_HOME"):
        dirs.append(_expand(os.environ["HF_LEROBOT_HOME"]))
    if os.environ.get("HF_HOME"):
        dirs.append(_expand(os.environ["HF_HOME"]) / "lerobot")
    if os.environ.get("XDG_CACHE_HOME"):
        dirs.append(_expand(os.environ["XDG_CACHE_HOME"]) / "huggingface" / "lerobot")
    dirs.append(Path.home() / ".cache" / "huggingface" / "lerobot")
    unique: list[Path] = []
    for d in dirs:
        if d not in unique:
            unique.append(d)
    return unique


def find_dataset(path_or_repo_id: str | Path, download: bool = False) -> Path:
    """A dataset root from a directory or an ``org/name`` repo id.

    A repo id is looked up as ``<home>/<org>/<name>`` under :func:`lerobot_home_dirs`; with
    ``download``, one found nowhere is fetched from the Hub into the first of them
    (:func:`inspector.data.hub.fetch_dataset`: the ``hub`` extra, never when ``HF_HUB_OFFLINE`` is set).

    Raises:
        InspectorError: not a dataset, or not found locally (the message says how to get it).
    """
    path = _expand(path_or_repo_id)
    if path.is_dir():
        if not (path / INFO_PATH).is_file():
            raise InspectorError(path / INFO_PATH, "not a LeRobot dataset: meta/info.json is missing")
        return path
    text = str(path_or_repo_id)
    if not REPO_ID.match(text):
        raise InspectorError(path, "no such dataset directory (give a directory or an org/name repo id)")
    homes = lerobot_home_dirs()
    for home in homes:
        if is_lerobot_dataset(home / text):
            return home / text
    if download:

        return fetch_dataset(text, homes[0] / text)
    where = ", ".join(str(h / text) for h in homes)
    if importlib.util.find_spec("lerobot") is not None:
        how = (f"download it with: python -c \"from lerobot.datasets.lerobot_dataset import "
               f"LeRobotDataset; LeRobotDataset('{text}')\"")
    else:
        major, minor = sys.version_info[:2]
        py = "" if (major, minor) >= (3, 12) else f"; this is Python {major}.{minor}"
        how = (f"pass the dataset's directory, or download it: with pip install 'inspector[hub]' "
               f"(then inspector fetches it), through LeRobot after pip install 'inspector[lerobot]' "
               f"(needs Python >= 3.12{py}), or with: huggingface-cli download "
               f"{text} --repo-type dataset --local-dir {homes[0] / text}")
    raise InspectorError(text, f"dataset not found locally (looked in {where}); {how}")
