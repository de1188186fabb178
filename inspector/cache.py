"""Per-rollout metrics kept on disk, so a second ``report`` (or opening a rollout in the app, or
exporting it) does not decode its videos again.

Entries live in the user's cache directory (``$INSPECTOR_CACHE_DIR``, else
``$XDG_CACHE_HOME/inspector``, else ``~/.cache/inspector``), never in the session, so read-only
sessions work. An entry's key covers everything its numbers depend on: every file of the rollout
and of its GT (path, size, modification time), the joint-limit margin, and the code that computes
them (the package version and the metric modules' source), so a changed input or a new release
never reads a stale entry. Entries are written atomically; an unreadable one is a miss. A cache
directory that cannot be written turns the cache off with one warning.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

ENV_DIR = "INSPECTOR_CACHE_DIR"
# The app's in-memory frame cache (JPEGs sent to browsers, shared by every tab) [MiB].
DEFAULT_FRAME_CACHE_MB = 256
SCHEMA = "inspector.metrics-cache/1"
# The modules whose code decides the cached numbers.
_METRIC_MODULES = ("analysis/metrics.py", "analysis/sweep.py", "analysis/video_metrics.py", "analysis/timeline.py",
                   "analysis/video_action.py",
                   "robot/kinematics.py", "units.py", "data/ground_truth.py", "report/rows.py", "data/video.py")


def default_dir() -> Path:
    """Where entries live (see the module docstring)."""
    if os.environ.get(ENV_DIR):
        return Path(os.path.expanduser(os.environ[ENV_DIR]))
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "inspector"


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """Package version + the metric modules' source, hashed: entries of other code never match."""
    from importlib import metadata

    h = hashlib.sha256(SCHEMA.encode())
    try:
        h.update(metadata.version("inspector").encode())
    except metadata.PackageNotFoundError:
        pass
    here = Path(__file__).resolve().parent
    for name in _METRIC_MODULES:
        try:
            h.update((here / name).read_bytes())
        except OSError:
            h.update(name.encode())
    return h.hexdigest()[:16]


def _file_state(path: Path) -> list[Any]:
    try:
        st = path.stat()
        return [str(path), st.st_size, st.st_mtime_ns]
    except OSError:
        return [str(path), None, None]


def rollout_key(rollout, gt, limit_margin_deg: float) -> str:
    """The cache key of a rollout's metrics (see the module docstring).

    Args:
        rollout: a :class:`inspector.data.session.Rollout`.
        gt: its :class:`inspector.data.ground_truth.GroundTruth`.
        limit_margin_deg: the joint-limit margin the numbers were computed with [deg].
    """
    root = Path(rollout.root).resolve()
    files = sorted(p for p in root.rglob("*") if p.is_file())
    state = {
        "code": code_fingerprint(),
        "rollout": str(root),
        "units": rollout.units.to_json(),
        "files": [_file_state(p) for p in files],
        "gt": {"source": gt.source, "dataset_key": list(gt.dataset_key) if gt.dataset_key else None,
               "files": [_file_state(Path(p)) for p in gt.files],
               "clips": {v: list(c.key) for v, c in sorted(gt.clips.items())}},
        "limit_margin_deg": float(limit_margin_deg),
    }
    return hashlib.sha256(json.dumps(state, sort_keys=True, default=str).encode()).hexdigest()


class MetricsCache:
    """Get and put per-rollout records (JSON objects) by key.

    Args:
        root: the cache directory (default :func:`default_dir`).
        enabled: False makes every get a miss and every put a no-op (``--no-cache``).
    """

    def __init__(self, root: str | Path | None = None, enabled: bool = True) -> None:
        self.root = Path(root) if root is not None else default_dir()
        self.enabled = enabled
        self._dir = self.root / "metrics"
        self._warned = False
        self._lock = threading.Lock()

    def _path(self, key: str) -> Path:
        return self._dir / key[:2] / f"{key}.json"

    def get(self, key: str) -> dict[str, Any] | None:
        """The record stored under ``key``, or None (missing, unreadable, or another schema)."""
        if not self.enabled:
            return None
        try:
            record = json.loads(self._path(key).read_text())
        except (OSError, ValueError, RecursionError):
            return None
        return record if isinstance(record, dict) and record.get("schema") == SCHEMA else None

    def put(self, key: str, record: dict[str, Any]) -> None:
        """Store ``record`` under ``key`` (atomically; a failure to write only warns, once)."""
        if not self.enabled:
            return
        path = self._path(key)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=".", suffix=".tmp", dir=path.parent)
            try:
                with os.fdopen(fd, "w") as fh:
                    # dumps, not dump: dump streams through the pure-Python encoder (5x slower)
                    fh.write(json.dumps({**record, "schema": SCHEMA}, allow_nan=False))
                os.replace(tmp, path)
            except BaseException:
                Path(tmp).unlink(missing_ok=True)
                raise
        except (OSError, ValueError) as exc:
            with self._lock:
                if not self._warned:
                    self._warned = True
                    print(f"warning: metrics cache {self._dir} not written ({exc}); continuing without it",
                          file=sys.stderr)
