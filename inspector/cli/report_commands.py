"""The commands that measure and decide: ``report``, ``compare``, ``rank``, ``agreement``."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..schema import json_text
from . import flags as flag
from .options import (
    dataset_argument,
    decision_arguments,
    emit,
    jobs_argument,
    measures,
    no_cache_argument,
    ray_argument,
    rollout_measure_arguments,
)


def _cmd_report(args: argparse.Namespace) -> int:
    from ..report.build import build_report, format_report

    thresholds = None
    if args.sanity or args.sanity_config:
        from ..report.sanity import load_thresholds

        thresholds = load_thresholds(args.sanity_config)  # a bad file fails before any work
    report = build_report(args.paths, dataset=args.dataset, jobs=args.jobs, use_cache=not args.no_cache,
                          limit_margin_deg=args.limit_margin, ray=args.ray, calibration=args.calibration,
                          outcome_source=args.outcome_source, measures=measures(args))
    if thresholds is not None:
        from ..report.sanity import add_sanity

        add_sanity(report, thresholds)
    if args.html:
        from ..report.html import write_report_html

        print(f"wrote {write_report_html(report, args.html, sources=args.paths)}", file=sys.stderr)
        if not (args.json or args.text):  # the page is what was asked for: the tables only on request
            return 0
    emit(json_text(report, indent=2) if args.json else format_report(report))
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from ..report.compare import build_comparison, format_comparison

    comparison = build_comparison(args.a, args.b, dataset=args.dataset, jobs=args.jobs,
                                  use_cache=not args.no_cache, limit_margin_deg=args.limit_margin,
                                  outcome_source=args.outcome_source, measures=measures(args))
    emit(json_text(comparison, indent=2) if args.json else format_comparison(comparison))
    return 0


def _cmd_rank(args: argparse.Namespace) -> int:
    from ..report.ranking import build_ranking, format_ranking

    result = build_ranking(args.paths, n_bootstrap=args.bootstrap, seed=args.seed)
    if args.html:
        from ..report.decision_html import write_ranking_html

        print(f"wrote {write_ranking_html(result, args.html)}", file=sys.stderr)
    emit(json_text(result, indent=2) if args.json else format_ranking(result))
    return 0


def _cmd_agreement(args: argparse.Namespace) -> int:
    from ..report.agreement import build_agreement, format_agreement

    result = build_agreement(args.imagined, args.real, by=args.by, match=dict(args.match or []),
                             imagined_source=args.imagined_source, real_source=args.real_source,
                             n_bootstrap=args.bootstrap, seed=args.seed)
    if args.html:
        from ..report.decision_html import write_agreement_html

        print(f"wrote {write_agreement_html(result, args.html)}", file=sys.stderr)
    emit(json_text(result, indent=2) if args.json else format_agreement(result))
    return 0


def add_report(sub: Any) -> None:
    p = sub.add_parser("report", help="drift metrics as tables or JSON")
    p.add_argument("paths", nargs="+", help="sessions, rollouts, DreamZero-SO101 source dirs or LeRobot "
                                             "datasets (a directory or org/name in the local cache)")
    p.add_argument("--json", action="store_true")
    dataset_argument(p)
    jobs_argument(p, "worker processes (1 computes in this process; with --ray, the local Ray instance's CPUs "
                     "or a cluster's tasks at once)")
    p.add_argument("--no-cache", action="store_true",
                   help="neither read nor write the metrics cache ($INSPECTOR_CACHE_DIR, else ~/.cache/inspector)")
    p.add_argument("--html", metavar="OUT.html",
                   help="write one self-contained page (tables, figures; opens offline) instead of printing "
                        "the tables (--json or --text prints them too)")
    p.add_argument("--text", action="store_true", help="with --html, print the text tables as well")
    p.add_argument("--sanity", action="store_true",
                   help="add the verdict of the five sanity tests (chunk fidelity, latent stability, joint "
                        "coherence, multi-task disambiguation, autoregressive rollout)")
    p.add_argument("--sanity-config", metavar="FILE.json",
                   help="thresholds of the sanity tests over the defaults (implies --sanity; see docs/report.md)")
    ray_argument(p, "compute the rollouts")
    rollout_measure_arguments(p)
    p.set_defaults(func=_cmd_report)



def add_compare(sub: Any) -> None:
    p = sub.add_parser("compare", help="two evaluations rollout by rollout (e.g. two checkpoints)")
    p.add_argument("a", help="session, rollout or DreamZero-SO101 source dir (A)")
    p.add_argument("b", help="the same for B; deltas are B - A")
    p.add_argument("--json", action="store_true")
    dataset_argument(p)
    jobs_argument(p, "worker processes (1 computes in this process)")
    no_cache_argument(p)
    rollout_measure_arguments(p, calibration=False)
    p.set_defaults(func=_cmd_compare)



def add_rank(sub: Any) -> None:
    p = sub.add_parser("rank", help="rank sessions (checkpoints) from blind A/B votes (Bradley-Terry), "
                                    "else by success rate")
    p.add_argument("paths", nargs="+", metavar="PATH", help="session directories (two or more)")
    decision_arguments(p)
    p.set_defaults(func=_cmd_rank)



def add_agreement(sub: Any) -> None:
    p = sub.add_parser("agreement", help="does success judged in imagination rank checkpoints as real success does")
    p.add_argument("--imagined", nargs="+", required=True, metavar="PATH",
                   help="sessions whose outcomes were judged in the world model's imagination")
    p.add_argument("--real", nargs="+", required=True, metavar="PATH",
                   help="sessions of the same checkpoints and tasks on the robot or in a simulator")
    p.add_argument("--by", choices=("success", "progress"), default="success",
                   help="compare success rates (default) or mean progress")
    p.add_argument("--match", type=flag.key_value("IMAGINED=REAL"), action="append", metavar="IMAGINED=REAL",
                   help="an imagined checkpoint's name as the real side calls it; repeat")
    for side in ("imagined", "real"):
        p.add_argument(f"--{side}-source", choices=("label", "file", "sim", "recording"), default=None,
                       help=f"read only this outcome source on the {side} side (default: each rollout's "
                            "effective outcome, label > file > sim > recording)")
    decision_arguments(p)
    p.set_defaults(func=_cmd_agreement)

