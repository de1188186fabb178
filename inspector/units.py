"""Dataset units -> URDF radians, mapped by joint *name*, never by position.

SO-101 datasets store six joints named ``shoulder_pan.pos ... gripper.pos``:

- arm joints in **degrees** (LeRobot >= 0.5 default, ``arm_units="degrees"``), or in the legacy
  **-100..100** range (``arm_units="range100"``: -100 and 100 are the two ends of the calibrated range,
  mapped linearly onto the URDF limits);
- the gripper in **0..100** (0 closed), mapped linearly onto the URDF gripper limits.

Values are never clamped: a prediction past a limit stays past it, so it can be shown.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

JOINT_NAMES: tuple[str, ...] = (
    "shoulder_pan",
    "shoulder_lift",
    "elbow_flex",
    "wrist_flex",
    "wrist_roll",
    "gripper",
)
ARM_JOINTS = JOINT_NAMES[:5]
GRIPPER_JOINT = "gripper"

# URDF limits [rad], from urdf/so101/so101.urdf (tests check they agree).
JOINT_LIMITS_RAD: dict[str, tuple[float, float]] = {
    "shoulder_pan": (-1.91986, 1.91986),
    "shoulder_lift": (-1.74533, 1.74533),
    "elbow_flex": (-1.69, 1.69),
    "wrist_flex": (-1.65806, 1.65806),
    "wrist_roll": (-2.74385, 2.84121),
    "gripper": (-0.174533, 1.74533),
}

ArmUnits = Literal["degrees", "range100"]
ARM_UNITS: tuple[str, ...] = ("degrees", "range100")
GRIPPER_UNITS = "0..100"


def canonical_joint_name(name: str) -> str:
    """``"shoulder_pan.pos"`` -> ``"shoulder_pan"``; names without the suffix pass through."""
    return name[: -len(".pos")] if name.endswith(".pos") else name


def joint_order(names: Sequence[str], source: str = "joint names") -> npt.NDArray[np.int64]:
    """Indices that reorder columns named ``names`` into :data:`JOINT_NAMES` order.

    Raises:
        ValueError: a joint is missing, unknown or repeated (the message lists what is available).
    """
    canon = [canonical_joint_name(n) for n in names]
    unknown = [n for n in canon if n not in JOINT_NAMES]
    if unknown or len(set(canon)) != len(canon) or len(canon) != len(JOINT_NAMES):
        raise ValueError(
            f"{source}: expected the 6 SO-101 joints {list(JOINT_NAMES)}, found {list(names)}"
        )
    return np.array([canon.index(j) for j in JOINT_NAMES], dtype=np.int64)


@dataclass(frozen=True)
class Units:
    """How a dataset or session stores joint values.

    Attributes:
        arm: ``"degrees"`` or ``"range100"`` (legacy -100..100).
        gripper: always ``"0..100"`` (0 closed).
        guessed: True when the arm mode was detected from the values rather than stated.
    """

    arm: ArmUnits = "degrees"
    gripper: str = GRIPPER_UNITS
    guessed: bool = False

    def label(self) -> str:
        arm = "degrees" if self.arm == "degrees" else "-100..100"
        return f"arm {arm}, gripper {self.gripper}" + (" (guessed)" if self.guessed else "")

    def to_json(self) -> dict[str, str]:
        return {"arm": self.arm, "gripper": self.gripper}


def _limits_arrays() -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    lo = np.array([JOINT_LIMITS_RAD[j][0] for j in JOINT_NAMES])
    hi = np.array([JOINT_LIMITS_RAD[j][1] for j in JOINT_NAMES])
    return lo, hi


def to_radians(values: npt.ArrayLike, units: Units) -> npt.NDArray[np.float64]:
    """Dataset units -> URDF joint angles.

    Args:
        values: (..., 6) joint values in :data:`JOINT_NAMES` order, dataset units.
        units: the dataset's units.

    Returns:
        (..., 6) float64 joint angles [rad], not clamped.
    """
    v = np.asarray(values, dtype=np.float64)
    lo, hi = _limits_arrays()
    out = np.empty_like(v)
    if units.arm == "degrees":
        out[..., :5] = np.deg2rad(v[..., :5])
    else:  # -100..100 spans the calibrated range, i.e. the URDF limits
        out[..., :5] = lo[:5] + (v[..., :5] + 100.0) / 200.0 * (hi[:5] - lo[:5])
    out[..., 5] = lo[5] + v[..., 5] / 100.0 * (hi[5] - lo[5])
    return out


def from_radians(q: npt.ArrayLike, units: Units) -> npt.NDArray[np.float64]:
    """Inverse of :func:`to_radians`: (..., 6) [rad] -> dataset units."""
    q = np.asarray(q, dtype=np.float64)
    lo, hi = _limits_arrays()
    out = np.empty_like(q)
    if units.arm == "degrees":
        out[..., :5] = np.rad2deg(q[..., :5])
    else:
        out[..., :5] = (q[..., :5] - lo[:5]) / (hi[:5] - lo[:5]) * 200.0 - 100.0
    out[..., 5] = (q[..., 5] - lo[5]) / (hi[5] - lo[5]) * 100.0
    return out


def limits_in_units(units: Units) -> npt.NDArray[np.float64]:
    """(6, 2) lower/upper joint limits expressed in the dataset's units."""
    lo, hi = _limits_arrays()
    return np.stack([from_radians(lo, units), from_radians(hi, units)], axis=1)


# How far past a URDF limit a value may rest before it counts as a violation [deg]: calibrated
# SO-101 data rests slightly past the URDF's elbow limit (elbow_flex 98.5 deg against 96.8).
DEFAULT_LIMIT_MARGIN_DEG = 2.0


def limit_margin_in_units(units: Units, margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG) -> npt.NDArray[np.float64]:
    """(6,) an angle margin [deg] expressed per joint in the dataset's units."""
    per_rad = from_radians(np.ones(6), units) - from_radians(np.zeros(6), units)  # units per radian
    return np.abs(per_rad) * np.deg2rad(margin_deg)


def guess_arm_units(values: npt.ArrayLike) -> tuple[Units, str]:
    """Guess the arm mode when nobody stated it; the result is marked ``guessed``.

    Legacy -100..100 data never leaves [-100, 100]; degrees on an SO-101 usually do (the lift and
    elbow rest near -100 / +95). Only values beyond that range prove degrees; otherwise we assume
    degrees, LeRobot's current default, and say so.

    Returns:
        The units and a one-line reason to show the user.
    """
    arm = np.asarray(values, dtype=np.float64)[..., :5]
    finite = arm[np.isfinite(arm)]
    if finite.size and np.abs(finite).max() > 100.5:
        return Units("degrees", guessed=True), "arm units not stated; values beyond +-100 mean degrees"
    return Units("degrees", guessed=True), (
        "arm units not stated and the values fit both degrees and -100..100; assuming degrees "
        "(say arm_units='range100' for legacy data)"
    )


def parse_units(obj: object, source: str) -> Units:
    """Units from a JSON value: ``{"arm": "degrees"|"range100", "gripper": "0..100"}``."""
    if not isinstance(obj, dict):
        raise ValueError(f"{source}: 'units' must be an object like {{\"arm\": \"degrees\"}}")
    arm = obj.get("arm", "degrees")
    if arm not in ARM_UNITS:
        raise ValueError(f"{source}: units.arm must be one of {list(ARM_UNITS)}, found {arm!r}")
    gripper = obj.get("gripper", GRIPPER_UNITS)
    if gripper != GRIPPER_UNITS:
        raise ValueError(f"{source}: units.gripper must be {GRIPPER_UNITS!r}, found {gripper!r}")
    return Units(arm=arm, gripper=gripper)
