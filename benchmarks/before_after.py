"""``inspector report`` before and after a change, measured in one run (the cost of a new metric).

    python benchmarks/before_after.py BEFORE [AFTER] [--reps N] [--quick] [--sessions ...]
    python benchmarks/before_after.py --without-sanity [--after REV] [--reps N] [--sessions video]

BEFORE and AFTER are git revisions of this repository (AFTER: the working tree as it is). Each is
exported (``git archive``) into a temporary directory and run from there with the same Python, on
the sessions of ``benchmarks/run.py``'s ``report`` rows (the demo; 1,000 rollouts without video;
200 with video; ``--quick``: 300 and 60, as ``run.py --quick``; ``--sessions`` picks some of
``demo``, ``many``, ``video``), alternating which goes first, each run with a fresh metrics cache.

``--without-sanity`` measures the sanity measures alone: both sides run the same code (AFTER, or
``--after REV``), "before" with ``INSPECTOR_SANITY_MEASURES=off`` (no seams, completion, joint
coherence, video quality or break: :mod:`inspector.analysis.measures_switch`); the figure's
target is then the measures' share of the report's CPU, ``(after - before) / after < --share``.

Prints, per session, the median CPU seconds of the whole process tree (user + system: what the
change costs, steadier than wall time on a shared machine), the median wall time, the median peak
RSS of the largest process of the tree, and the after/before ratios. ``--latest NAME`` also merges
them into ``benchmarks/latest.json`` as figures ``NAME_<session>`` (ours: CPU after; baseline: CPU
before; target: after/before < ``--budget``, or the share above) and rewrites the table in
``benchmarks/README.md``.
"""

from __future__ import annotations

import argparse
import os
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


Run = tuple[float, float, float]  # CPU s, wall s, peak RSS MiB


def report_once(tree: Path, session: Path, cache: Path, extra_env: dict[str, str] | None = None) -> Run:
    """(CPU seconds of the process tree, wall seconds, peak RSS [MiB] of its largest process) of
    ``inspector report SESSION --json``, run from ``tree``: ``python -m`` puts the working
    directory first on the import path, so from anywhere else (this repository's root) it would
    import that directory's ``inspector``."""
    env = {**os.environ, "PYTHONPATH": str(tree), "INSPECTOR_CACHE_DIR": str(cache), **(extra_env or {})}
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "inspector", "report", str(session.resolve()), "--json"],
                            env=env, cwd=tree, stdout=subprocess.DEVNULL)
    # wait4: this process's own usage (its workers' included), not every child's so far
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise SystemExit(f"error: {session}: inspector report exited {proc.returncode}")
    return usage.ru_utime + usage.ru_stime, wall, usage.ru_maxrss / 1024


def cost_figures(name: str, medians: dict[str, dict[str, Run]], before: str, reps: int,
                 budget: float, share: float | None = None) -> list[dict]:
    """``latest.json`` figures of the medians ``{session: {side: (CPU s, wall s, RSS MiB)}}``;
    with ``share``, the target is the cost's share of the after side's CPU."""
    figures = []
    for session, m in medians.items():
        (cpu_b, wall_b, rss_b), (cpu_a, wall_a, rss_a) = m["before"], m["after"]
        cost = (cpu_a - cpu_b) / cpu_a
        if share is None:
            target, ok = f"CPU after/before < {budget}", cpu_a / cpu_b < budget
        else:
            target, ok = f"measures < {share:.0%} of report CPU", cost < share
        figures.append({"name": f"{name}_{session}", "ours": round(cpu_a, 2), "unit": "s", "target": target,
                        "ok": ok, "ours_rss_mib": round(rss_a), "baseline": round(cpu_b, 2),
                        "baseline_rss_mib": round(rss_b),
                        "note": f"CPU seconds of the process tree, after vs before {before} (before_after.py, medians "
                                f"of {reps}): {cpu_a / cpu_b:.2f}x CPU, {cost:.1%} of the report's CPU; "
                                f"wall {wall_b:.1f} -> {wall_a:.1f} s; peak RSS {rss_b:.0f} -> {rss_a:.0f} MiB; "
                                f"{time.strftime('%Y-%m-%d')}, load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores",
                        "ratio": round(cpu_b / cpu_a, 3)})
    return figures


def record(name: str, medians: dict[str, dict[str, Run]], before: str, reps: int,
           budget: float, share: float | None = None) -> None:
    import json

    import table

    latest = table.merge(table.load(), cost_figures(name, medians, before, reps, budget, share))
    table.LATEST.write_text(json.dumps(latest, indent=2) + "\n")
    table.write(latest)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", nargs="?", help="git revision measured first as the baseline, e.g. HEAD~3")
    parser.add_argument("after", nargs="?", help="git revision (default: the working tree)")
    parser.add_argument("--without-sanity", action="store_true",
                        help="before: the same code as after, with the sanity measures switched off")
    parser.add_argument("--after", dest="after_rev", metavar="REV", help="with --without-sanity: the revision both run")
    parser.add_argument("--sessions", nargs="+", choices=("demo", "many", "video"), default=("demo", "many", "video"),
                        help="which sessions to report (default: all three)")
    parser.add_argument("--share", type=float, default=0.15,
                        help="with --without-sanity: the measures' share of the report's CPU to stay under")
    parser.add_argument("--reps", type=int, default=2, help="runs of each side per session (default 2)")
    parser.add_argument("--quick", action="store_true", help="smaller sessions (300 and 60 rollouts)")
    parser.add_argument("--latest", metavar="NAME", help="merge the figures into benchmarks/latest.json as NAME_<session>")
    parser.add_argument("--budget", type=float, default=1.15, help="after/before CPU ratio the figures must stay under")
    args = parser.parse_args(argv)
    if args.without_sanity == (args.before is not None):
        parser.error("give BEFORE (a revision) or --without-sanity, one of them")

    with tempfile.TemporaryDirectory(prefix="inspector-before-after-") as tmp_name:
        tmp = Path(tmp_name)
        after_rev = args.after_rev or args.after
        after_tree = export_tree(after_rev, tmp / "after") if after_rev else REPO
        envs: dict[str, dict[str, str]] = {"before": {}, "after": {}}
        if args.without_sanity:
            trees = {"before": after_tree, "after": after_tree}
            label = f"{after_rev[:7] if after_rev else 'the working tree'} without the sanity measures"
            envs["before"] = {"INSPECTOR_SANITY_MEASURES": "off"}
        else:
            trees, label = {"before": export_tree(args.before, tmp / "before"), "after": after_tree}, args.before
        many, with_video = (300, 60) if args.quick else (1000, 200)
        makers = {"demo": ("report_demo", lambda: REPO / "sessions" / "demo"),
                  "many": (f"report_{many}", lambda: make_eval_session(tmp / "many", many, video=False)),
                  "video": (f"report_{with_video}_video", lambda: make_eval_session(tmp / "video", with_video, video=True))}
        sessions = {makers[k][0]: makers[k][1]() for k in ("demo", "many", "video") if k in args.sessions}
        runs: dict[tuple[str, str], list[Run]] = {}
        for rep in range(args.reps):
            order = ["before", "after"] if rep % 2 == 0 else ["after", "before"]
            for name, session in sessions.items():
                for side in order:
                    cache = tmp / f"cache-{name}-{side}-{rep}"
                    run = report_once(trees[side], session, cache, envs[side])
                    print(f"{name} {side} rep {rep}: CPU {run[0]:.1f} s, wall {run[1]:.1f} s, peak RSS {run[2]:.0f} MiB",
                          file=sys.stderr, flush=True)
                    runs.setdefault((name, side), []).append(run)
        medians = {name: {side: tuple(statistics.median(r[i] for r in runs[(name, side)]) for i in range(3))
                          for side in ("before", "after")} for name in sessions}
        if args.latest:
            record(args.latest, medians, label, args.reps, args.budget,  # type: ignore[arg-type]
                   args.share if args.without_sanity else None)
        print("| session | CPU before | CPU after | CPU ratio | cost share | wall before | wall after | RSS before | RSS after |")
        print("|---|---|---|---|---|---|---|---|---|")
        for name in sessions:
            (cpu_b, wall_b, rss_b), (cpu_a, wall_a, rss_a) = medians[name]["before"], medians[name]["after"]
            print(f"| {name} | {cpu_b:.1f} s | {cpu_a:.1f} s | {cpu_a / cpu_b:.2f} | {(cpu_a - cpu_b) / cpu_a:.1%} "
                  f"| {wall_b:.1f} s | {wall_a:.1f} s | {rss_b:.0f} MiB | {rss_a:.0f} MiB |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
