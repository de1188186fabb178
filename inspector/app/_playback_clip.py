"""Playback as a video the browser plays by itself.

Stepping ``<img>`` frames from the server plays only as fast as the page paints, and a page paints
no faster than its 3D canvas renders: on a browser without a GPU (WebGL in software) a frame of the
arms takes 0.1-1 s, so image playback was a slideshow there. A ``<video>`` element is decoded and
presented by the browser's compositor, off the page's main thread, so the same frames play at
their rate whatever the 3D view costs. On Play the tab encodes, per video panel, the very frames
the panel would show step by step (display size, from the frame cache) into an H.264 clip at the
playback rate, and swaps it in where the images were, started at the step playback is at; the
arms, readout and plot cursors then follow the clip as the page plays it (see ``._clip_clock``).
Pause (or a seek, a speed or view change, or the rollout's end) brings the images back.
"""

from __future__ import annotations

import base64
from collections.abc import Callable, Iterator, Sequence

import numpy as np
import numpy.typing as npt

from ..data.video import encode_h264_bytes

# Steps per clip: playback is cut into segments at multiples of this, each encoded once (1-2 ms a
# frame per panel, panels in parallel) and kept in the frame cache. Every swap to the next segment
# restarts the browser's video element, which costs a page without a GPU seconds: segments are
# long rather than many (20 s at 30 steps/s).
CLIP_STEPS = 600
# Off: playback steps images only, as before clips (the benchmark's baseline).
ENABLED = True


class ClipNotWanted(Exception):
    """Encoding stopped part-way: the playback it was for has ended (Pause, a seek, a closed tab)."""


def encode_clip(uris: Sequence[str], fps: float, wanted: Callable[[], bool] = lambda: True) -> str:
    """JPEG data URIs, one per step, -> an H.264 MP4 data URI playing them at ``fps`` frames/s.

    A URI repeated from the previous step (a GT frame that stays) is decoded once; H.264 codes the
    repeat in a few bytes. ``wanted`` is asked every :data:`ASK_EVERY` frames: once it says no,
    the encoding stops (:class:`ClipNotWanted`) rather than finishing a clip no one will see.
    """
    # A keyframe every 2 s: a clip swapped in mid-segment (``#t=``) seeks quickly.
    data = encode_h264_bytes(_decoded(uris, wanted), fps, crf=26, preset="ultrafast", name="playback clip",
                             keyframe_every=max(1, round(2 * fps)))
    return "data:video/mp4;base64," + base64.b64encode(data).decode("ascii")


# Frames between two looks at whether a clip is still wanted (a tenth of a second of encoding).
ASK_EVERY = 60


def _decoded(uris: Sequence[str], wanted: Callable[[], bool]) -> Iterator[npt.NDArray[np.uint8]]:
    import simplejpeg

    previous, rgb = None, None
    for i, uri in enumerate(uris):
        if i % ASK_EVERY == ASK_EVERY - 1 and not wanted():
            raise ClipNotWanted
        if uri != previous:
            rgb = simplejpeg.decode_jpeg(base64.b64decode(uri.split(",", 1)[1]), colorspace="RGB")
            previous = uri
        assert rgb is not None  # the first uri always differs from None
        yield rgb
