"""What the app says in place of the arm for a video-only rollout (no ``actions.npy``: a simulated
evaluation run without recordings, a policy server's predicted video).

Such a rollout has views, their PSNR and video measures, and maybe an outcome; it has no joints,
so there is no arm to draw, no joint drift and no joint plot: rather than empty panels the app
says so, in the card and where the plots would be.
"""

from __future__ import annotations

from html import escape as esc

from ..analysis.timeline import RolloutTimeline

# Marks the card row and the panel note, so a page (and its tests) can find them.
NOTE_CLASS = "inspector-video-only"


def is_video_only(tl: RolloutTimeline | None) -> bool:
    return tl is not None and not tl.has_joints


def joints_row(tl: RolloutTimeline) -> tuple[str, str]:
    """The card's row in place of the 3D scene legend."""
    gt = ", ".join(tl.gt.views)
    seen = f"imagined views beside {'the GT views (' + gt + ')' if gt else 'no GT view'}"
    return ("joints", f"<span class='{NOTE_CLASS}'><b>none: video only</b> (no predicted or executed "
                      f"arm in this rollout; {esc(seen)})</span>")


def panel_note() -> str:
    """Shown where the joint drift and joint plots would be."""
    return (f"<div class='{NOTE_CLASS}' style='font-size:0.8rem;color:#6b7280;padding:4px'>Video only: this "
            "rollout has no joints, so no arm, no joint drift and no joint plot. Its views, their PSNR "
            "and video measures are in the Video tab.</div>")
