"""Fetch a LeRobot dataset from the Hugging Face Hub into the local LeRobot cache (optional).

Only when a user names a dataset by ``org/name`` that is not on disk yet, and only with the
``hub`` extra installed (``pip install 'inspector[hub]'``, i.e. ``huggingface_hub``). It lands where
LeRobot itself keeps datasets (:func:`inspector.data.lerobot_dataset.lerobot_home_dirs`), so the next
run finds it locally. ``HF_HUB_OFFLINE=1`` is honoured: nothing is fetched, and the error says how
to get the dataset. ``HF_ENDPOINT`` is honoured too (a mirror, or a local server in tests).

A download goes to a temporary sibling directory and is renamed into place once complete, so an
interrupted one never leaves a half dataset that looks whole.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from .._files import mkdtemp_sibling
from ..errors import InspectorError

_TRUE = ("1", "true", "yes", "on")


def offline() -> bool:
    """True when the user asked the Hub libraries to stay offline (``HF_HUB_OFFLINE``)."""
    return os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in _TRUE


def hub_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("huggingface_hub") is not None


def fetch_dataset(repo_id: str, dest: Path) -> Path:
    """Download dataset ``repo_id`` to ``dest`` (a progress bar shows on stderr).

    Raises:
        InspectorError: offline, ``huggingface_hub`` missing, or the download failed (one line,
            naming the repo and the endpoint).
    """
    how = (f"get it with: huggingface-cli download {repo_id} --repo-type dataset --local-dir {dest}, "
           "or pass the dataset's directory")
    if offline():
        raise InspectorError(repo_id, f"dataset not in the local cache ({dest}) and HF_HUB_OFFLINE is set; {how}")
    if not hub_available():
        raise InspectorError(repo_id, f"dataset not in the local cache ({dest}); install the hub extra "
                                      f"(pip install 'inspector[hub]') to download it, or {how}")
    from huggingface_hub import snapshot_download

    endpoint = os.environ.get("HF_ENDPOINT", "https://huggingface.co")
    dest.parent.mkdir(parents=True, exist_ok=True)
    staging = mkdtemp_sibling(dest)  # mkdtemp's 0700 would stick to the dataset once renamed
    try:
        snapshot_download(repo_id, repo_type="dataset", local_dir=staging)
        if not (staging / "meta" / "info.json").is_file():
            raise InspectorError(repo_id, f"downloaded from {endpoint}, but it is not a LeRobot dataset "
                                          "(no meta/info.json)")
        os.replace(staging, dest)
    except InspectorError:
        raise
    except Exception as exc:  # network, authentication, a repo that does not exist: one line
        raise InspectorError(repo_id, f"cannot download from {endpoint} ({type(exc).__name__}: {exc}); {how}") from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return dest
