"""Export one rollout as a Rerun recording from Python (what ``inspector export`` writes).

Usage::

    python examples/export_rollout.py OUT.rrd [SESSION [TAG]]    # default: the demo's tempo_0.8x

Builds the rollout's timeline (every metric over time, shared with the app and the report), prints
a few of its figures, and writes the recording: both arms, the videos, the drift series. Open it
with ``rerun OUT.rrd``.
"""

from __future__ import annotations

import sys

from inspector import build_timeline, open_session
from inspector.data.sources import BUNDLED_DEMO
from inspector.export import write_recording


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    out = argv[0]
    session = open_session(argv[1] if len(argv) > 1 else BUNDLED_DEMO)
    tag = argv[2] if len(argv) > 2 else "tempo_0.8x"
    timeline = build_timeline(session.rollouts[tag])
    print(f"{tag}: {timeline.n_chunks} chunks, tempo {timeline.tempo:.2f}, "
          f"time-aligned drift {timeline.time_aligned_drift.mean():.1f} deg, "
          f"best-match drift {timeline.best_match_drift.mean():.1f} deg")
    path = write_recording(timeline, out, progress=None)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
