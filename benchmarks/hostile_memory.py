"""Peak memory and time of each command on input at the documented limits (docs/reliability.md,
"Limits"): every one must stay under 1.5 GB of peak RSS.

    python benchmarks/hostile_memory.py [--only CASE...] [--rev REV] [--keep DIR]

Cases (each built in a temporary directory, then run as ``python -m inspector ...``):

- ``outcomes``: ``outcomes import`` of a JSON-lines file just under the accepted 64 MiB (5.5
  million one-field rows, none naming a rollout of the session).
- ``votes``: ``rank`` of two sessions with 75,000 votes between them (each votes.json ~20 MB,
  under the 32 MB JSON limit).
- ``chain``: ``rank`` of 1,000 sessions compared in a chain (999 votes).
- ``latents``: ``report`` of two rollouts with 8,000 x 1 latent vectors each.
- ``video_only``: ``report`` of a video-only rollout at the longest that a rollout may be.

Each command runs in a small wrapper process that reads its peak RSS from
``getrusage(RUSAGE_CHILDREN)`` (the largest process of the tree: ``report`` runs with ``--jobs 1``,
so the command is one process). ``--rev REV`` runs the code of a git revision instead of the
working tree (exported with ``git archive``), for the figures before a change.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
LIMIT_MIB = 1536

_WRAPPER = """
import resource, subprocess, sys
out, err, *argv = sys.argv[1:]
with open(out, "w") as o, open(err, "w") as e:
    rc = subprocess.call(argv, stdout=o, stderr=e)
u = resource.getrusage(resource.RUSAGE_CHILDREN)
print(rc, u.ru_maxrss)
"""


def measure(tree: Path, work: Path, *argv: object, timeout: float = 1800) -> tuple[int, float, float, str]:
    """(exit code, peak RSS [MiB], wall [s], last line of stderr) of ``python -m inspector ARGV``
    run from ``tree``."""
    out, err = work / "cmd.out", work / "cmd.err"
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _WRAPPER, str(out), str(err), sys.executable, "-m", "inspector",
                           *map(str, argv)], capture_output=True, text=True, timeout=timeout, check=True,
                          cwd=tree, env={**os.environ, "PYTHONPATH": str(tree)})
    wall = time.perf_counter() - start
    rc, peak_kib = done.stdout.split()
    lines = err.read_text(errors="replace").strip().splitlines()
    return int(rc), int(peak_kib) / 1024, wall, (lines[-1][:160] if lines else "")


def _session(root: Path, name: str = "s", tags: Sequence[str] = ("r0",), **rollout: object) -> Path:
    from inspector.data.session import SessionWriter

    with SessionWriter.create(root / name, model={"name": name}) as w:
        for tag in tags:
            w.add_rollout(tag, kind="single_chunk", actions=np.zeros((1, 9, 6)), **rollout)  # type: ignore[arg-type]
    return (root / name).resolve()


def _write_votes(roots: list[Path], pairs: list[tuple[int, int, str]]) -> None:
    """Each vote in both of its sessions' votes.json, as the app writes them."""
    per_session: dict[int, list[dict]] = {i: [] for i in range(len(roots))}
    for k, (a, b, answer) in enumerate(pairs):
        vote = {"id": f"{k:032x}", "time": "2026-11-28T12:00:00+00:00", "answer": answer,
                "a": {"session": str(roots[a]), "name": roots[a].name, "rollout": "r0", "progress": None},
                "b": {"session": str(roots[b]), "name": roots[b].name, "rollout": "r0", "progress": None},
                "note": ""}
        per_session[a].append(vote)
        per_session[b].append(vote)
    for i, votes in per_session.items():
        (roots[i] / "votes.json").write_text(json.dumps({"schema": "inspector.votes/1", "votes": votes}))


def case_outcomes(root: Path) -> list[object]:
    session = _session(root, "s", ["r0"])
    row = '{"tag":"x"}\n'  # the shortest row the reader accepts: one per 12 bytes
    path = root / "outcomes.jsonl"
    with path.open("w") as f:
        f.write('{"tag":"r0","success":true}\n')
        f.write(row * ((64 << 20) // len(row) - 10))
    assert path.stat().st_size < 64 << 20
    return ["outcomes", "import", path, session]


def case_votes(root: Path) -> list[object]:
    roots = [_session(root, f"s{i}", ["r0"]) for i in range(2)]
    rng = np.random.default_rng(0)
    answers = rng.choice(["a", "b", "tie"], size=75_000, p=[0.5, 0.4, 0.1])
    _write_votes(roots, [(0, 1, str(a)) for a in answers])
    assert max((r / "votes.json").stat().st_size for r in roots) < 32 << 20
    return ["rank", "--json", *roots]


def case_chain(root: Path) -> list[object]:
    first = _session(root, "s0000", ["r0"])
    roots = [first]
    for i in range(1, 1000):  # copies of one session: writing 1,000 takes minutes
        dest = root / f"s{i:04d}"
        subprocess.run(["cp", "-r", str(first), str(dest)], check=True)
        roots.append(dest.resolve())
    rng = np.random.default_rng(0)
    _write_votes(roots, [(i, i + 1, "a" if rng.random() < 0.5 else "b") for i in range(999)])
    return ["rank", "--json", *roots]


def case_latents(root: Path) -> list[object]:
    from inspector.data.session import SessionWriter

    with SessionWriter.create(root / "s", model={"name": "s"}) as w:
        for episode in range(2):
            w.add_rollout(f"r{episode}", kind="single_chunk", actions=np.zeros((1, 9, 6)), episode_index=episode,
                          latents=np.random.default_rng(episode).normal(episode, 1.0, (8000, 1)))
    return ["report", "--json", "--no-cache", "--jobs", "1", root / "s"]


def case_video_only(root: Path) -> list[object]:
    from inspector.data.session import MAX_VIDEO_ONLY_STEPS, SessionWriter

    frames = np.full((4, 32, 48, 3), 100, np.uint8)
    with SessionWriter.create(root / "s", model={"name": "s"}) as w:
        w.add_rollout("long", kind="autoregressive", actions=None, n_chunks=MAX_VIDEO_ONLY_STEPS // 1000,
                      horizon=1000, executed_per_chunk=1000, frames_per_chunk=1, fps=5.0,
                      videos={"front": frames})
    return ["report", "--json", "--no-cache", "--jobs", "1", root / "s"]


CASES: dict[str, Callable[[Path], list[object]]] = {
    "outcomes": case_outcomes, "votes": case_votes, "chain": case_chain, "latents": case_latents,
    "video_only": case_video_only,
}


def export_tree(rev: str, dest: Path) -> Path:
    dest.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(REPO), "archive", rev], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    return dest


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", choices=list(CASES), default=list(CASES))
    parser.add_argument("--rev", default=None, help="run this git revision's code (default: the working tree)")
    parser.add_argument("--keep", type=Path, default=None, help="build the inputs here and keep them")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="inspector-hostile-") as tmp:
        base = args.keep or Path(tmp)
        tree = export_tree(args.rev, Path(tmp) / "tree") if args.rev else REPO
        print(f"{'case':<11} {'exit':>4} {'peak MiB':>9} {'wall s':>7}  ok  last line of stderr")
        failed = 0
        for name in args.only:
            work = base / name
            work.mkdir(parents=True, exist_ok=True)
            argv = CASES[name](work)
            rc, peak, wall, last = measure(tree, work, *argv)
            ok = rc in (0, 2) and peak < LIMIT_MIB
            failed += not ok
            print(f"{name:<11} {rc:>4} {peak:>9.0f} {wall:>7.1f}  {'yes' if ok else 'NO '} {last}", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
