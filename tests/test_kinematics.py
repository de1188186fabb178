"""SO-101 URDF, unit mapping and batched FK, cross-checked against yourdfpy."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from inspector.robot.description import load_urdf, resolved_urdf_text, urdf_path
from inspector.robot.kinematics import So101Kinematics, kinematics
from inspector.units import (
    JOINT_LIMITS_RAD,
    JOINT_NAMES,
    Units,
    from_radians,
    guess_arm_units,
    joint_order,
    limits_in_units,
    to_radians,
)


def test_urdf_limits_match_unit_table():
    root = ET.parse(urdf_path()).getroot()
    for joint in root.iter("joint"):
        if joint.get("type") == "revolute":
            limit = joint.find("limit")
            assert (float(limit.get("lower")), float(limit.get("upper"))) == JOINT_LIMITS_RAD[joint.get("name")]
            assert joint.find("axis").get("xyz") == "0 0 1"


def test_gripper_frame_at_zero():
    p = kinematics().gripper_frame_poses(np.zeros((1, 6)))[0, :3, 3]
    np.testing.assert_allclose(p, [0.391, 0.0, 0.227], atol=1e-3)


@pytest.mark.slow
def test_fk_matches_yourdfpy_on_random_in_limit_configurations():
    rng = np.random.default_rng(0)
    lo = np.array([JOINT_LIMITS_RAD[j][0] for j in JOINT_NAMES])
    hi = np.array([JOINT_LIMITS_RAD[j][1] for j in JOINT_NAMES])
    q = rng.uniform(lo, hi, size=(500, 6))
    fk = kinematics()
    ours = fk.link_poses(q)
    urdf = load_urdf(load_meshes=False).urdf
    worst = 0.0
    for i in range(len(q)):
        urdf.update_cfg({j: q[i, k] for k, j in enumerate(JOINT_NAMES)})  # by name, not position
        for link in fk.link_names:
            worst = max(worst, np.abs(urdf.get_transform(link, "base_link")[:3, 3] - ours[link][i, :3, 3]).max())
    assert worst <= 1e-6


@pytest.mark.slow
def test_fk_matches_pytorch_kinematics_for_every_link():
    """A second independent parser of the same URDF (its chain is parsed in float32: ~5e-7 m)."""
    torch = pytest.importorskip("torch")
    pk = pytest.importorskip("pytorch_kinematics")
    chain = pk.build_chain_from_urdf(resolved_urdf_text()[0].encode()).to(dtype=torch.float64)
    names = chain.get_joint_parameter_names()
    q = np.random.default_rng(3).uniform(-1.5, 1.5, size=(300, 6))
    theirs = chain.forward_kinematics(torch.from_numpy(q[:, [JOINT_NAMES.index(n) for n in names]]))
    ours = kinematics().link_poses(q)
    for link in kinematics().link_names:
        np.testing.assert_allclose(ours[link], theirs[link].get_matrix().numpy(), atol=2e-6)


@pytest.mark.slow
def test_the_command_line_never_loads_torch(tmp_path):
    """FK, metrics and video run on numpy alone: no command pays torch's ~2 s and ~250 MB."""
    import subprocess
    import sys

    code = ("import sys; from inspector.cli import main; "
            "main(['report', sys.argv[1], '--json', '--jobs', '1', '--no-cache']); "
            "assert 'torch' not in sys.modules, 'torch was imported'")
    demo = Path(__file__).resolve().parents[1] / "sessions" / "demo" / "rollouts" / "single_f000"
    out = subprocess.run([sys.executable, "-c", code, str(demo)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr


def test_batched_equals_per_sample():
    rng = np.random.default_rng(1)
    q = rng.uniform(-1, 1, size=(20, 6))
    fk = So101Kinematics()
    batched = fk.gripper_frame_poses(q)
    single = np.stack([fk.gripper_frame_poses(q[i:i + 1])[0] for i in range(len(q))])
    np.testing.assert_allclose(batched, single, atol=1e-12)


def test_fk_rejects_wrong_width():
    with pytest.raises(ValueError, match=r"\(T, 6\)"):
        kinematics().link_poses(np.zeros((3, 5)))


def test_units_degrees_and_gripper():
    values = np.array([[90.0, -45.0, 0.0, 10.0, -180.0, 0.0], [0, 0, 0, 0, 0, 100.0]])
    q = to_radians(values, Units("degrees"))
    np.testing.assert_allclose(q[0, :5], np.deg2rad(values[0, :5]))
    assert q[0, 5] == pytest.approx(JOINT_LIMITS_RAD["gripper"][0])  # 0 = closed = lower limit
    assert q[1, 5] == pytest.approx(JOINT_LIMITS_RAD["gripper"][1])


def test_units_legacy_range100_maps_onto_limits():
    q = to_radians(np.array([[-100, 100, 0, -100, 100, 50.0]]), Units("range100"))[0]
    assert q[0] == pytest.approx(JOINT_LIMITS_RAD["shoulder_pan"][0])
    assert q[1] == pytest.approx(JOINT_LIMITS_RAD["shoulder_lift"][1])
    assert q[2] == pytest.approx(0.0)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-300, 300), min_size=6, max_size=6), st.sampled_from(["degrees", "range100"]))
def test_units_round_trip_and_never_clamp(values, arm):
    units = Units(arm)
    v = np.array([values])
    np.testing.assert_allclose(from_radians(to_radians(v, units), units), v, atol=1e-9)


def test_limits_in_units_degrees():
    lim = limits_in_units(Units("degrees"))
    assert lim[1, 0] == pytest.approx(-100.0, abs=0.01)  # shoulder_lift -1.74533 rad
    assert lim[5].tolist() == pytest.approx([0.0, 100.0])


def test_joint_order_by_name():
    names = ["gripper.pos", "wrist_roll.pos", "wrist_flex.pos", "elbow_flex.pos", "shoulder_lift.pos", "shoulder_pan.pos"]
    order = joint_order(names)
    assert [names[i] for i in order][0] == "shoulder_pan.pos"
    with pytest.raises(ValueError, match="expected the 6 SO-101 joints"):
        joint_order(names[:5] + ["elbow.pos"])


def test_unit_guess_says_so():
    units, reason = guess_arm_units(np.array([[0, -104.0, 98, 60, 0, 10]]))
    assert units.guessed and units.arm == "degrees" and "degrees" in reason
    assert "(guessed)" in units.label()


def test_link_origins_equal_full_poses_for_every_link():
    q = np.random.default_rng(2).uniform(-1.5, 1.5, size=(50, 6))
    fk = kinematics()
    poses = fk.link_poses(q)
    for link in fk.link_names[1:]:
        np.testing.assert_allclose(fk.link_origins(q, link), poses[link][:, :3, 3], atol=1e-12)
    with pytest.raises(ValueError, match="not in the SO-101 URDF"):
        fk.link_origins(q, "tool0")
