"""An evaluation loop that writes a session: what a model's evaluation script does with ``SessionWriter``.

Usage::

    python examples/evaluation_loop.py OUT_SESSION [--dataset DATASET]

The "model" here is a stand-in that predicts each 24-step chunk as the real joints plus a bias
that grows along the horizon; replace ``predict_chunk`` with a call to your model. Every chunk is
a single-chunk sample (one real observation in, one chunk out) at 8 start frames spread over each
episode, stored with the dataset as its ground truth, so ``inspector report OUT_SESSION`` and
``inspector serve OUT_SESSION`` measure it at once. The session appears at OUT_SESSION only when
the loop finishes without error.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from inspector import SessionWriter
from inspector.data import open_dataset
from inspector.data.sources import BUNDLED_DEMO

HORIZON = 24  # actions per predicted chunk
SAMPLES_PER_EPISODE = 8


def predict_chunk(state: np.ndarray, future: np.ndarray) -> np.ndarray:
    """(HORIZON, 6) predicted joints [deg, gripper 0..100] from the current state (6,).

    A stand-in for a model: the real future plus a bias of up to 3 deg on every joint.
    """
    del state  # a real model conditions on it (and on camera frames)
    return future + np.linspace(0.0, 3.0, len(future))[:, None]


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="the session directory to write")
    parser.add_argument("--dataset", default=str(BUNDLED_DEMO / "dataset"), help="a LeRobot dataset")
    args = parser.parse_args(argv)

    dataset = open_dataset(args.dataset)
    with SessionWriter.create(args.out, model={"name": "biased-oracle", "checkpoint": "example"},
                              dataset=args.dataset) as session:
        for ref in dataset.episodes:
            episode = dataset.episode(ref.index)
            starts = np.linspace(0, episode.length - HORIZON, SAMPLES_PER_EPISODE).astype(int)
            for start in starts:
                future = episode.action[start:start + HORIZON]
                chunk = predict_chunk(episode.state[start], future)
                session.add_rollout(f"ep{ref.index:03d}_f{start:04d}", kind="single_chunk",
                                    actions=chunk[None], episode_index=ref.index, start_frame=int(start),
                                    prompt=episode.task, fps=episode.fps)
    print(f"wrote {args.out}: {SAMPLES_PER_EPISODE * len(dataset.episodes)} single-chunk samples")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
