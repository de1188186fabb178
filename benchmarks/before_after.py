"""``inspector report`` before and after a change, measured in one run (the cost of a new metric).

    python benchmarks/before_after.py BEFORE [AFTER] [--reps N] [--quick]

BEFORE and AFTER are git revisions of this repository (AFTER: the working tree as it is). Each is
exported (``git archive``) into a temporary directory and run from there with the same Python, on
the sessions of ``benchmarks/run.py``'s ``report`` rows (the demo; 1,000 rollouts without video;
200 with video; ``--quick``: 300 and 60, as ``run.py --quick``), alternating which goes first, each
run with a fresh metrics cache. Prints, per session,
the median CPU seconds of the whole process tree (user + system: what the change costs, steadier
than wall time on a shared machine), the median wall time, and the after/before ratios.
``--latest NAME`` also merges them into ``benchmarks/latest.json`` as figures ``NAME_<session>``
(ours: CPU after; baseline: CPU before; target: after/before < ``--budget``) and rewrites the
table in ``benchmarks/README.md``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from eval_session import make_eval_session

REPO = Path(__file__).resolve().parents[1]


def export_tree(rev: str, dest: Path) -> Path:
    """The revision's files at ``dest`` (its ``inspector`` package importable from there)."""
    dest.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(REPO), "archive", rev], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    return dest


def report_once(tree: Path, session: Path, cache: Path) -> tuple[float, float]:
    """(CPU seconds of the process tree, wall seconds) of ``inspector report SESSION --json``,
    run from ``tree``: ``python -m`` puts the working directory first on the import path, so from
    anywhere else (this repository's root) it would import that directory's ``inspector``."""
    env = {**os.environ, "PYTHONPATH": str(tree), "INSPECTOR_CACHE_DIR": str(cache)}
    before, start = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    subprocess.run([sys.executable, "-m", "inspector", "report", str(session.resolve()), "--json"], env=env,
                   cwd=tree, stdout=subprocess.DEVNULL, check=True)
    wall, after = time.perf_counter() - start, resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def cost_figures(name: str, medians: dict[str, dict[str, tuple[float, float]]], before: str, reps: int,
                 budget: float) -> list[dict]:
    """``latest.json`` figures of the medians ``{session: {side: (CPU s, wall s)}}``."""
    figures = []
    for session, m in medians.items():
        (cpu_b, wall_b), (cpu_a, wall_a) = m["before"], m["after"]
        figures.append({"name": f"{name}_{session}", "ours": cpu_a, "unit": "s", "target": f"CPU after/before < {budget}",
                        "ok": cpu_a / cpu_b < budget, "ours_rss_mib": None, "baseline": cpu_b, "baseline_rss_mib": None,
                        "note": f"CPU seconds of the process tree, after vs before {before} (before_after.py, medians "
                                f"of {reps}): {cpu_a / cpu_b:.2f}x CPU; wall {wall_b:.1f} -> {wall_a:.1f} s",
                        "ratio": cpu_b / cpu_a})
    return figures


def record(name: str, medians: dict[str, dict[str, tuple[float, float]]], before: str, reps: int,
           budget: float) -> None:
    import json

    import table

    latest = table.merge(table.load(), cost_figures(name, medians, before, reps, budget))
    table.LATEST.write_text(json.dumps(latest, indent=2) + "\n")
    table.write(latest)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", help="git revision measured first as the baseline, e.g. HEAD~3")
    parser.add_argument("after", nargs="?", help="git revision (default: the working tree)")
    parser.add_argument("--reps", type=int, default=2, help="runs of each side per session (default 2)")
    parser.add_argument("--quick", action="store_true", help="smaller sessions (300 and 60 rollouts)")
    parser.add_argument("--latest", metavar="NAME", help="merge the figures into benchmarks/latest.json as NAME_<session>")
    parser.add_argument("--budget", type=float, default=1.15, help="after/before CPU ratio the figures must stay under")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="inspector-before-after-") as tmp_name:
        tmp = Path(tmp_name)
        trees = {"before": export_tree(args.before, tmp / "before"),
                 "after": export_tree(args.after, tmp / "after") if args.after else REPO}
        many, with_video = (300, 60) if args.quick else (1000, 200)
        sessions = {"report_demo": REPO / "sessions" / "demo",
                    f"report_{many}": make_eval_session(tmp / "many", many, video=False),
                    f"report_{with_video}_video": make_eval_session(tmp / "video", with_video, video=True)}
        runs: dict[tuple[str, str], list[tuple[float, float]]] = {}
        for rep in range(args.reps):
            order = ["before", "after"] if rep % 2 == 0 else ["after", "before"]
            for name, session in sessions.items():
                for side in order:
                    cache = tmp / f"cache-{name}-{side}-{rep}"
                    runs.setdefault((name, side), []).append(report_once(trees[side], session, cache))
        medians = {name: {side: (statistics.median(c for c, _ in runs[(name, side)]),
                                 statistics.median(w for _, w in runs[(name, side)])) for side in ("before", "after")}
                   for name in sessions}
        if args.latest:
            record(args.latest, medians, args.before, args.reps, args.budget)
        print("| session | CPU before | CPU after | CPU ratio | wall before | wall after | wall ratio |")
        print("|---|---|---|---|---|---|---|")
        for name in sessions:
            cpu = {side: medians[name][side][0] for side in ("before", "after")}
            wall = {side: medians[name][side][1] for side in ("before", "after")}
            print(f"| {name} | {cpu['before']:.1f} s | {cpu['after']:.1f} s | {cpu['after'] / cpu['before']:.2f} "
                  f"| {wall['before']:.1f} s | {wall['after']:.1f} s | {wall['after'] / wall['before']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
