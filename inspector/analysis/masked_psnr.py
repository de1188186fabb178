"""PSNR inside and outside the projected GT arm: is the imagined video's error in the arm or the scene?

Each imagined frame measured (32-63 a clip: :data:`inspector.analysis.camera_measures.MASKED_FRAMES`)
is compared with its GT frame (resized to the imagined size, as for the
whole-frame PSNR) twice: over the pixels the GT arm covers in the GT frame (the mask of
:func:`inspector.robot.silhouette.arm_masks` for the GT joints at that step, drawn at the
imagined frame's size), and over the rest. Each is a PSNR of its own pixels (peak 255, all three
channels), averaged over the frames as the whole-frame PSNR is. A frame whose mask (or its
complement) holds no pixel adds nothing to that side; a side no frame has pixels on is null, with
a reason.
"""

from __future__ import annotations

from typing import TypedDict

import numpy as np
import numpy.typing as npt

MIN_MSE = 1e-10  # as metrics.psnr: identical pixels give a large, finite PSNR


class MaskedPsnr(TypedDict):
    """One view's ``video_psnr_masked``: mean PSNR [dB] inside the GT arm's mask and outside it."""

    arm: float | None
    scene: float | None
    frames: int  # frames compared (a GT frame and a mask)
    note: str | None  # why a side is null


def split_squared_error(imagined: npt.NDArray[np.uint8], gt: npt.NDArray[np.uint8], mask: npt.NDArray[np.bool_]
                        ) -> tuple[float, int, float, int]:
    """(squared error summed in the mask, its values, outside it, its values) of one frame pair.

    Args:
        imagined, gt: (H, W, 3) uint8 frames of one size.
        mask: (H, W) bool, True on the arm.
    """
    # as metrics.psnr: |p - g| in uint8, its square in uint16, sums of rows in uint32 (a row of
    # 16,384 pixels of three channels cannot overflow), the mask's values picked from the same
    # squares (less than half the time of the squared error per pixel in int32)
    diff = np.maximum(imagined, gt)
    diff -= np.minimum(imagined, gt)
    squares = diff.astype(np.uint16)
    squares *= squares
    channels = imagined.shape[2] if imagined.ndim == 3 else 1
    by_row = squares.reshape(squares.shape[0], -1)
    total = int(by_row.sum(axis=1, dtype=np.uint32).sum(dtype=np.uint64))
    inside = int(by_row[np.repeat(mask, channels, axis=1)].sum(dtype=np.uint64))
    n_in = int(np.count_nonzero(mask))
    return float(inside), n_in * channels, float(total - inside), (mask.size - n_in) * channels


def psnr_of(squared_error: float, values: int) -> float:
    """PSNR [dB] of ``values`` 8-bit values whose squared errors sum to ``squared_error``."""
    return float(10.0 * np.log10(255.0 ** 2 / max(squared_error / values, MIN_MSE)))


class MaskedPsnrAccumulator:
    """Per-frame arm and scene PSNR of frame pairs fed one at a time."""

    def __init__(self) -> None:
        self._arm: list[float] = []
        self._scene: list[float] = []
        self.frames = 0

    def add(self, imagined: npt.NDArray[np.uint8], gt: npt.NDArray[np.uint8], mask: npt.NDArray[np.bool_]) -> None:
        se_in, n_in, se_out, n_out = split_squared_error(imagined, gt, mask)
        self.frames += 1
        if n_in:
            self._arm.append(psnr_of(se_in, n_in))
        if n_out:
            self._scene.append(psnr_of(se_out, n_out))

    def result(self, note: str | None = None) -> MaskedPsnr:
        """The record; ``note`` says why nothing was compared (where no frame was)."""
        arm = round(float(np.mean(self._arm)), 4) if self._arm else None
        scene = round(float(np.mean(self._scene)), 4) if self._scene else None
        if note is None and self.frames == 0:
            note = "no imagined frame with a GT frame to compare"
        elif note is None and arm is None:
            note = "the projected GT arm covers no pixel of the frames compared"
        elif note is None and scene is None:
            note = "the projected GT arm covers every pixel of the frames compared"
        return {"arm": arm, "scene": scene, "frames": self.frames, "note": note}


def not_measured(note: str) -> MaskedPsnr:
    """A view's record where nothing could be compared, saying why."""
    return {"arm": None, "scene": None, "frames": 0, "note": note}


__all__ = ["MaskedPsnr", "MaskedPsnrAccumulator", "not_measured", "psnr_of", "split_squared_error"]
