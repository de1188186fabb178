"""An evaluation's worth of rollouts, written the way a user's evaluation script writes them.

    python benchmarks/eval_session.py DEST -n 200 [--no-video]

N autoregressive 60x24x6 rollouts of the bundled demo's episode 0 (each a seeded perturbation
of the demo's 60-chunk rollout), written with :class:`inspector.SessionWriter`, GT from
``sessions/demo/dataset``; with video, each carries the demo's two 540-frame H.264 views.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "sessions" / "demo"
SOURCE = DEMO / "rollouts" / "overrun_60chunks"


def make_eval_session(dest: str | Path, n: int, video: bool = True, seed: int = 0) -> Path:
    """Write ``n`` rollouts to a new session at ``dest`` (replacing one left by an earlier run)."""
    from inspector import SessionWriter

    base = np.load(SOURCE / "actions.npy")
    rng = np.random.default_rng(seed)
    videos = {v: SOURCE / "video" / f"{v}.mp4" for v in ("front", "wrist")} if video else None
    with SessionWriter.create(dest, name=Path(dest).name, overwrite=True,
                              model={"name": "benchmark", "checkpoint": f"seed {seed}"},
                              dataset=str(DEMO / "dataset")) as session:
        for i in range(n):
            drift = rng.normal(scale=0.3, size=base.shape).cumsum(axis=0)  # grows chunk by chunk
            session.add_rollout(f"ep000_{i:04d}", kind="autoregressive", actions=base + drift,
                                episode_index=0, start_frame=0,
                                prompt="Pick the red cube" if i % 2 == 0 else "Lift the red cube",
                                videos=videos)
    return Path(dest)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dest")
    parser.add_argument("-n", type=int, default=200)
    parser.add_argument("--no-video", action="store_true")
    args = parser.parse_args(argv)
    make_eval_session(args.dest, args.n, video=not args.no_video)
    print(f"wrote {args.n} rollouts to {args.dest}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
