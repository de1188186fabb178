"""Simplified SO-101 meshes: vertex clustering (the app, per start) and decimated copies for
``.rrd`` files (made once and cached on disk).

The CAD meshes are tessellated far finer than a viewer needs (~480k triangles per arm, most of
them under half a millimetre). Two passes bring an arm to ~40k triangles:

1. vertex clustering on a 0.5 mm grid, which merges the sliver triangles that stall a quadric
   decimator on these parts (fast-simplification alone stops at ~25 % of the input);
2. quadric decimation (fast-simplification) to :data:`KEEP_FRACTION` of what is left.

Results live in ``$INSPECTOR_CACHE_DIR`` or ``$XDG_CACHE_HOME/inspector/meshes`` (default
``~/.cache/inspector/meshes``), keyed by the source file's SHA-256 and the decimation settings, so
a changed mesh or setting never serves a stale copy. A cache that cannot be written falls back to
a per-user temporary directory.
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np
import numpy.typing as npt

CELL_M = 5e-4  # clustering grid [m]
KEEP_FRACTION = 0.35  # of the clustered faces, kept by the quadric pass
MIN_FACES = 200
_SETTINGS = f"v1-cell{CELL_M:g}-keep{KEEP_FRACTION:g}-min{MIN_FACES}"


def cache_dir() -> Path:
    """The mesh cache directory (created on demand)."""
    from .cache import default_dir

    path = default_dir() / "meshes"
    try:
        path.mkdir(parents=True, exist_ok=True)
        if not os.access(path, os.W_OK):
            raise PermissionError(path)
    except OSError:
        path = Path(tempfile.gettempdir()) / f"inspector-meshes-{os.getuid()}"
        path.mkdir(parents=True, exist_ok=True)
    return path


def decimated_mesh(src: str | Path, cache: Path | None = None) -> Path:
    """Path of a decimated binary-STL copy of ``src``, made on first use.

    Args:
        src: a triangle mesh file trimesh can read (the SO-101 parts are STL).
        cache: directory to keep the copy in (default :func:`cache_dir`).

    Returns:
        The cached ``<stem>-<key>.stl``; ``key`` hashes the source bytes and the settings.
    """
    src = Path(src)
    stat = src.stat()
    return _decimated(str(src.resolve()), stat.st_mtime_ns, stat.st_size, str(cache or cache_dir()))


@functools.lru_cache(maxsize=256)
def _decimated(src: str, mtime_ns: int, size: int, cache: str) -> Path:
    """One hash per part and process (an arm uses the same servo mesh seven times)."""
    digest = hashlib.sha256(Path(src).read_bytes())
    digest.update(_SETTINGS.encode())
    dest = Path(cache) / f"{Path(src).stem}-{digest.hexdigest()[:16]}.stl"
    if not dest.is_file():
        vertices, faces = decimate(*_load(Path(src)))
        _write_stl_atomic(dest, vertices, faces)
    return dest


def decimate(vertices: npt.ArrayLike, faces: npt.ArrayLike
             ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """(V, 3) [m], (F, 3) -> a coarser mesh of the same shape (see the module docstring)."""
    import fast_simplification

    v, f = cluster_vertices(vertices, faces, CELL_M)
    target = max(MIN_FACES, int(len(f) * KEEP_FRACTION))
    if target < len(f):
        v, f = fast_simplification.simplify(v, f, target_count=target)
    return np.asarray(v, np.float64), np.asarray(f, np.int64)


def cluster_vertices(vertices: npt.ArrayLike, faces: npt.ArrayLike, cell: float
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Merge the vertices sharing a ``cell``-sized grid cell; drop the faces that collapse.

    Winding is kept, so face normals still point outwards. Faces repeated after the merge
    (the same three vertices) are kept once.
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    keys = np.round(v / cell).astype(np.int64)
    _, cell_of, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    cell_of = cell_of.reshape(-1)
    merged = np.zeros((len(counts), 3))
    np.add.at(merged, cell_of, v)
    merged /= counts[:, None]
    nf = cell_of[f]
    keep = (nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])
    nf = nf[keep]
    _, first = np.unique(np.sort(nf, axis=1), axis=0, return_index=True)
    return merged, nf[np.sort(first)]


def _load(src: Path) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    import trimesh

    mesh = trimesh.load(str(src), force="mesh")
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _write_stl_atomic(dest: Path, vertices: npt.NDArray[np.float64], faces: npt.NDArray[np.int64]) -> None:
    import trimesh

    data = trimesh.Trimesh(vertices, faces, process=False).export(file_type="stl")
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, dest)  # concurrent writers produce the same bytes; last one wins
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
