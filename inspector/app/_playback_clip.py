"""Playback as a video the browser plays by itself.

Stepping ``<img>`` frames from the server plays only as fast as the page paints, and a page paints
no faster than its 3D canvas renders: on a browser without a GPU (WebGL in software) a frame of the
arms takes 0.1-1 s, so image playback was a slideshow there. A ``<video>`` element is decoded and
presented by the browser's compositor, off the page's main thread, so the same frames play at
their rate whatever the 3D view costs. On Play the tab encodes, per video panel, the very frames
the panel would show step by step (display size, from the frame cache) into an H.264 clip at the
playback rate, and swaps it in where the images were, started at the step playback is at; the
arms, readout and plot cursors keep following the server's clock. Pause (or a seek, a speed or
view change, or the rollout's end) brings the images back.
"""

from __future__ import annotations

import base64
import io
from fractions import Fraction
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

# Steps per clip: playback is cut into segments at multiples of this, each encoded once (1-2 ms a
# frame per panel, panels in parallel) and kept in the frame cache. Every swap to the next segment
# restarts the browser's video element, which costs a page without a GPU seconds: segments are
# long rather than many (20 s at 30 steps/s).
CLIP_STEPS = 600
# Off: playback steps images only, as before clips (the benchmark's baseline).
ENABLED = True
# Timestamps in milliseconds: any playback rate (0.25x of 30 fps = 7.5 fps) is exact enough.
_TIME_BASE_MS = 1000


def encode_clip(uris: Sequence[str], fps: float) -> str:
    """JPEG data URIs, one per step, -> an H.264 MP4 data URI playing them at ``fps`` frames/s.

    A URI repeated from the previous step (a GT frame that stays) is decoded once; H.264 codes the
    repeat in a few bytes. Frames are cropped to even sizes (4:2:0 chroma needs them).
    """
    import av
    import simplejpeg

    if not uris:
        raise ValueError("a playback clip needs at least one frame")
    buffer = io.BytesIO()
    with av.open(buffer, "w", format="mp4") as out:
        stream = None
        previous_uri, rgb = None, None
        for k, uri in enumerate(uris):
            if uri != previous_uri:
                rgb = _even(simplejpeg.decode_jpeg(base64.b64decode(uri.split(",", 1)[1]), colorspace="RGB"))
                previous_uri = uri
            assert rgb is not None
            if stream is None:
                stream = out.add_stream("libx264", rate=max(1, round(fps)))
                stream.width, stream.height, stream.pix_fmt = rgb.shape[1], rgb.shape[0], "yuv420p"
                stream.profile = "baseline"  # decodable by every browser that plays H.264
                stream.options = {"preset": "ultrafast", "crf": "26", "g": "60"}  # a keyframe every 2 s: quick seeks
                stream.codec_context.time_base = Fraction(1, _TIME_BASE_MS)
            if rgb.shape[:2] != (stream.height, stream.width):
                rgb = _fit(rgb, stream.width, stream.height)
            frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
            frame.pts = round(k * _TIME_BASE_MS / fps)
            frame.time_base = Fraction(1, _TIME_BASE_MS)
            for packet in stream.encode(frame):
                out.mux(packet)
        assert stream is not None
        for packet in stream.encode():
            out.mux(packet)
    return "data:video/mp4;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def _even(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    h, w = rgb.shape[0] & ~1, rgb.shape[1] & ~1
    return np.ascontiguousarray(rgb[:h, :w])


def _fit(rgb: npt.NDArray[np.uint8], width: int, height: int) -> npt.NDArray[np.uint8]:
    """Pad or crop to (height, width): a panel's frames share one size, this is only a safeguard."""
    out = np.zeros((height, width, 3), np.uint8)
    h, w = min(height, rgb.shape[0]), min(width, rgb.shape[1])
    out[:h, :w] = rgb[:h, :w]
    return out
