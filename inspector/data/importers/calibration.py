"""Joint calibrations: how another calibration's joint readings map onto the URDF's joint zeros.

The URDF is the SO-101 "new calibration" (joint zero = middle of the range, LeRobot >= PR #777).
Data recorded with LeRobot's earlier calibration (zero = the arm stretched out horizontally) reads
other numbers for the same pose. Each joint is mapped as ``urdf_deg = sign * (value - zero)``; the
gripper (0..100 in both) passes through unless a calibration says otherwise.

Named calibrations, each with where its numbers come from:

- ``none``: the values already use the URDF's zeros (new-calibration degrees).
- ``lerobot-legacy``: LeRobot's calibration before PR #777. huggingface/lerobot
  ``docs/source/backwardcomp.mdx`` and ``examples/backward_compatibility/replay.py``:
  ``shoulder_lift.pos = -(shoulder_lift - 90)`` ("the 0 position is changed by -90 degrees and the
  direction is reversed") and ``elbow_flex.pos -= 90``; the other joints keep their numbers.
- ``gr00t-so100``: the SO-100 data GR00T's ``so100`` embodiment was trained on (its ``stats.json``,
  which GR00T-Dreams' ``IDM_dump/global_metadata/so100`` copies: means near 113, 116, 109, 74, -43,
  16): ``lerobot-legacy`` plus a shoulder_pan centred on 90 instead of 0 (NVIDIA/Isaac-GR00T#156,
  "the values of shoulder_pan are centered on 90"; ``getting_started/examples/eval_gr00t_so100.py``
  starts the arm at ``[90, 90, 90, 90, -70, 30]``).

A user overrides any joint on top of a named calibration: ``gr00t-so100,shoulder_pan=0`` or
``none,wrist_roll=-90:-1`` (``JOINT=ZERO[:SIGN]``, ZERO in the data's units).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ...units import JOINT_NAMES

# joint -> (zero: the reading at the URDF's zero, sign: +1 same direction, -1 reversed)
JointMap = dict[str, tuple[float, float]]

_IDENTITY: JointMap = {j: (0.0, 1.0) for j in JOINT_NAMES}
# huggingface/lerobot docs/source/backwardcomp.mdx (PR #777): lift reversed about 90, elbow shifted by 90.
LEROBOT_LEGACY_OFFSETS: JointMap = {**_IDENTITY, "shoulder_lift": (90.0, -1.0), "elbow_flex": (90.0, 1.0)}
# NVIDIA/Isaac-GR00T#156 and eval_gr00t_so100.py: GR00T's SO-100 data centres shoulder_pan on 90.
GR00T_SO100_PAN_ZERO_DEG = 90.0
GR00T_SO100_OFFSETS: JointMap = {**LEROBOT_LEGACY_OFFSETS, "shoulder_pan": (GR00T_SO100_PAN_ZERO_DEG, 1.0)}

NAMED: dict[str, tuple[JointMap, str]] = {
    "none": (_IDENTITY, "values already use the URDF's joint zeros"),
    "lerobot-legacy": (LEROBOT_LEGACY_OFFSETS, "LeRobot's calibration before PR #777 (zero = arm stretched "
                                               "out); offsets from lerobot docs/source/backwardcomp.mdx"),
    "gr00t-so100": (GR00T_SO100_OFFSETS, "GR00T's SO-100 data (legacy LeRobot calibration, shoulder_pan "
                                         "centred on 90: Isaac-GR00T#156)"),
}

# More than this share of steps past a joint limit says the calibration is wrong, not the data.
WRONG_CALIBRATION_SHARE = 0.5


@dataclass(frozen=True)
class Calibration:
    """A named calibration, possibly with joints overridden by the user.

    Attributes:
        name: ``gr00t-so100``, ``lerobot-legacy``, ``none``.
        joints: joint -> (zero, sign), every joint of :data:`JOINT_NAMES`.
        overrides: the joints the user set (``JOINT=ZERO[:SIGN]``), as written.
        how: where the named calibration's numbers come from.
    """

    name: str
    joints: tuple[tuple[str, float, float], ...]
    overrides: tuple[str, ...] = ()
    how: str = ""

    @property
    def spec(self) -> str:
        """What ``--calibration`` takes to make this calibration again."""
        return ",".join([self.name, *self.overrides])

    def apply(self, values: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """(..., 6) readings in :data:`JOINT_NAMES` order -> the URDF's zeros (degrees, gripper 0..100)."""
        v = np.asarray(values, dtype=np.float64)
        zero = np.array([z for _, z, _ in self.joints])
        sign = np.array([s for _, _, s in self.joints])
        return sign * (v - zero)

    def describe(self) -> str:
        """One line: the name and every joint it moves, e.g. ``gr00t-so100: shoulder_pan = x - 90, ...``."""
        moved = [f"{j} = {'x' if s > 0 else '-x'}" + (f" {'-' if s * z > 0 else '+'} {abs(z):g}" if z else "")
                 for j, z, s in self.joints if (z, s) != (0.0, 1.0)]
        return f"{self.spec}: " + (", ".join(moved) if moved else "values as they are")

    def to_json(self) -> dict[str, object]:
        return {"name": self.name, "spec": self.spec, "how": self.how,
                "joints": {j: {"zero": z, "sign": s} for j, z, s in self.joints}}


def parse_calibration(spec: str | None, default: str) -> Calibration:
    """A :class:`Calibration` from ``--calibration``'s text (``None``: ``default``).

    ``NAME``, ``NAME,JOINT=ZERO[:SIGN],...`` or ``JOINT=ZERO[:SIGN],...`` (on top of ``default``).

    Raises:
        ValueError: an unknown name or joint, or a value that is no number (the message lists
            what is known).
    """
    parts = [p.strip() for p in (spec if spec is not None else default).split(",") if p.strip()]
    name = default
    if parts and "=" not in parts[0]:
        name = parts.pop(0)
    if name not in NAMED:
        raise ValueError(f"unknown calibration {name!r}; known: {', '.join(NAMED)} (then JOINT=ZERO[:SIGN] to "
                         "override a joint)")
    joints, how = dict(NAMED[name][0]), NAMED[name][1]
    for part in parts:
        joint, _, value = part.partition("=")
        joint = joint.strip().removeprefix("main_")
        if joint not in JOINT_NAMES:
            raise ValueError(f"{part!r}: no joint {joint!r}; joints: {', '.join(JOINT_NAMES)}")
        zero_text, _, sign_text = value.partition(":")
        try:
            zero, sign = float(zero_text), float(sign_text) if sign_text else 1.0
        except ValueError:
            raise ValueError(f"{part!r}: expected {joint}=ZERO or {joint}=ZERO:SIGN with numbers") from None
        if not np.isfinite(zero) or sign not in (1.0, -1.0):
            raise ValueError(f"{part!r}: ZERO must be a finite number and SIGN 1 or -1")
        joints[joint] = (zero, sign)
    return Calibration(name, tuple((j, *joints[j]) for j in JOINT_NAMES), tuple(parts), how)
