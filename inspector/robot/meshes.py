"""Simplified SO-101 meshes: vertex clustering (the app, per start) and decimated copies for
``.rrd`` files (made once and cached on disk).

The CAD meshes are tessellated far finer than a viewer needs (~480k triangles per arm, most of
them under half a millimetre). Two passes bring an arm to ~40k triangles:

1. vertex clustering on a 0.5 mm grid, which merges the sliver triangles that stall a quadric
   decimator on these parts (fast-simplification alone stops at ~25 % of the input);
2. quadric decimation (fast-simplification) to :data:`KEEP_FRACTION` of what is left.

Results live in ``$INSPECTOR_CACHE_DIR`` or ``$XDG_CACHE_HOME/inspector/meshes`` (default
``~/.cache/inspector/meshes``), keyed by the source file's SHA-256 and the decimation settings, so
a changed mesh or setting never serves a stale copy. A cache that cannot be written (said once,
as :func:`inspector.cache.note_unusable` says it) falls back to a per-user temporary directory, and
where that cannot be written either, to the full mesh: a larger recording of the same arm.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import os
import tempfile
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from .._files import mkstemp_sibling
from ..cache import default_dir, note_unusable

CELL_M = 5e-4  # clustering grid [m]
KEEP_FRACTION = 0.35  # of the clustered faces, kept by the quadric pass
MIN_FACES = 200
# v2: meshes read by our STL reader (the same triangles as trimesh found; vertex order, and so
# the last bit of a clustered vertex, may differ)
_SETTINGS = f"v2-cell{CELL_M:g}-keep{KEEP_FRACTION:g}-min{MIN_FACES}"


def cache_dir() -> Path:
    """The mesh cache directory (created on demand)."""
    path = default_dir() / "meshes"
    try:
        path.mkdir(parents=True, exist_ok=True)
        if not os.access(path, os.W_OK):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
    except OSError as exc:
        note_unusable(default_dir(), exc)
        path = _fallback_dir()
    return path


def _fallback_dir() -> Path:
    return Path(tempfile.gettempdir()) / f"inspector-meshes-{os.getuid()}"


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
    name = f"{Path(src).stem}-{digest.hexdigest()[:16]}.stl"
    if (Path(cache) / name).is_file():
        return Path(cache) / name
    vertices, faces = decimate(*_load(Path(src)))
    for directory in dict.fromkeys((Path(cache), _fallback_dir())):
        try:
            directory.mkdir(parents=True, exist_ok=True)
            _write_stl_atomic(directory / name, vertices, faces)
            return directory / name
        except OSError as exc:  # a full disk, a read-only one
            note_unusable(directory, exc)
    return Path(src)


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
    _, cell_of, counts = _unique_rows(keys, return_inverse=True, return_counts=True)
    cell_of = cell_of.reshape(-1)
    merged = np.zeros((len(counts), 3))
    np.add.at(merged, cell_of, v)
    merged /= counts[:, None]
    nf = cell_of[f]
    keep = (nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])
    nf = nf[keep]
    _, first = _unique_rows(np.sort(nf, axis=1), return_index=True)
    return merged, nf[np.sort(first)]


def _unique_rows(rows: npt.NDArray[np.int64], **kwargs: Any) -> tuple[Any, ...]:
    """``np.unique(rows, axis=0, **kwargs)``, with the rows packed into one int64 each.

    Sorting one int64 per row is several times quicker than numpy's sort of whole rows, and the
    packed keys order as the rows do, so the index, inverse and counts are the same (the unique
    values come back as packed keys: callers use only the others). Rows whose values span more
    than 21 bits are left to numpy.
    """
    if len(rows) == 0:
        return np.unique(rows, axis=0, **kwargs)
    shifted = rows - rows.min(axis=0)
    if shifted.max() >= 1 << 21:
        return np.unique(rows, axis=0, **kwargs)
    return np.unique((shifted[:, 0] << 42) | (shifted[:, 1] << 21) | shifted[:, 2], **kwargs)


# A binary STL: an 80-byte header, a uint32 triangle count, then 50 bytes per triangle.
_STL_HEADER = 84
_STL_TRIANGLE = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attributes", "<u2")])


def _load(src: Path) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """(V, 3), (F, 3) of a mesh file, a vertex shared by several triangles listed once.

    Binary STL (every SO-101 part) is read here, a few times quicker than through trimesh, whose
    import alone takes a second; anything else goes through trimesh.
    """
    data = src.read_bytes()
    count = int.from_bytes(data[80:_STL_HEADER], "little") if len(data) >= _STL_HEADER else -1
    if src.suffix.lower() != ".stl" or len(data) != _STL_HEADER + count * _STL_TRIANGLE.itemsize:
        import trimesh

        mesh = cast("trimesh.Trimesh", trimesh.load(str(src), force="mesh"))  # force="mesh": a Trimesh
        return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    corners = np.frombuffer(data, _STL_TRIANGLE, count, _STL_HEADER)["vertices"].reshape(-1, 3)
    return _merge_identical(corners + np.float32(0.0))  # a copy, with -0.0 made +0.0 (same bits)


def _merge_identical(corners: npt.NDArray[np.float32]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """A triangle soup's (3F, 3) corners -> unique vertices and faces indexing them.

    Corners are equal when their bits are (a float32 STL repeats a shared vertex exactly); a
    lexsort of the three coordinates' bits is several times quicker than ``np.unique(axis=0)``.
    """
    bits = corners.view(np.uint32)
    order = np.lexsort((bits[:, 2], bits[:, 1], bits[:, 0]))
    ordered = bits[order]
    first = np.ones(len(ordered), bool)
    first[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    vertex_of = np.empty(len(order), np.int64)
    vertex_of[order] = np.cumsum(first) - 1
    return corners[order[first]].astype(np.float64), vertex_of.reshape(-1, 3)


def _write_stl_atomic(dest: Path, vertices: npt.NDArray[np.float64], faces: npt.NDArray[np.int64]) -> None:
    """Write a binary STL (outward normals from the winding) through a temporary file."""
    triangles = np.zeros(len(faces), _STL_TRIANGLE)
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    triangles["normal"] = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    triangles["vertices"] = corners
    data = b"inspector decimated mesh".ljust(80, b" ") + len(faces).to_bytes(4, "little") + triangles.tobytes()
    fd, tmp = mkstemp_sibling(dest)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, dest)  # concurrent writers produce the same bytes; last one wins
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
