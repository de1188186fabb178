"""``inspector compare A B``: two evaluations of the same rollouts (two checkpoints, two models),
rollout by rollout.

Rows come from :func:`inspector.report.build.build_report` (its workers and metrics cache). Rollouts
pair by tag; those left pair by (episode, start frame, prompt, kind), tags sharing the longest
prefix first. Per pair:
both rows and the differences ``b - a`` (positive: B is worse). Over the pairs: how often each
side is better (lower wins), the mean difference and the rank agreement (Spearman), for the chunk
RMSE and, where GT joints exist, the time-aligned drift; per view, the same for the mean PSNR
(higher is better): how rollouts without joints (video only) compare. Whether a difference is
real, success included, is decided once per metric by its test (:mod:`.significance`). Each side
is named by the model and checkpoint its ``session.json`` states, else by its folder.
"""

from __future__ import annotations

import math
import os
import warnings
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..data.session import SESSION_FILE, is_rollout, is_session, read_json
from ..errors import InspectorError
from ..rows.rollout import nearest_tag as _nearest_tag
from ..stats import TIE_TOLERANCE, signed_rank_test
from .build import build_report
from .significance import metric_tests, verdict_lines

Row = dict[str, Any]
# Text output lists at most this many pairs (the largest differences).
MAX_TEXT_PAIRS = 30


def _start_key(r: Row) -> tuple:
    return (r["episode_index"], r["start_frame"], r["prompt"], r["kind"])


def pair_rows(rows_a: Sequence[Row], rows_b: Sequence[Row]) -> tuple[list[tuple[Row, Row, str]], list[Row], list[Row]]:
    """Pairs (a, b, paired_by) and the rows of each side left unpaired.

    By tag first (``paired_by`` "tag"); the rest by (episode, start frame, prompt, kind)
    ("start"), see :func:`_pair_by_start`.
    """
    by_tag_b: dict[str, list[Row]] = defaultdict(list)
    for r in rows_b:
        by_tag_b[r["tag"]].append(r)
    pairs, rest_a = [], []
    for r in rows_a:
        same = by_tag_b.get(r["tag"])
        if same:
            pairs.append((r, same.pop(0), "tag"))
        else:
            rest_a.append(r)
    rest_b = [r for rs in by_tag_b.values() for r in rs]
    groups: dict[tuple, tuple[list[Row], list[Row]]] = defaultdict(lambda: ([], []))
    for side, rows in ((0, rest_a), (1, rest_b)):
        for r in rows:
            groups[_start_key(r)][side].append(r)
    unmatched_a, unmatched_b = [], []
    for group_a, group_b in groups.values():
        matched, left_a, left_b = _pair_by_start(group_a, group_b)
        pairs += [(a, b, "start") for a, b in matched]
        unmatched_a += left_a
        unmatched_b += left_b
    return pairs, sorted(unmatched_a, key=_tag), sorted(unmatched_b, key=_tag)


def _tag(r: Row) -> str:
    return r["tag"]


def _pair_by_start(rows_a: list[Row], rows_b: list[Row]) -> tuple[list[tuple[Row, Row]], list[Row], list[Row]]:
    """Rollouts with the same start: tags that share the longest prefix first (``prompt_train``
    with ``prompt_train_v2``), the rest in tag order. Candidates are each tag's neighbours in the
    other side's sorted tags, so a group of thousands costs n log n."""
    a, b = sorted(rows_a, key=_tag), sorted(rows_b, key=_tag)
    if not a or not b:
        return [], a, b
    tags_a, tags_b = [r["tag"] for r in a], [r["tag"] for r in b]
    edges = {(i, _nearest_tag(tags_b, t)) for i, t in enumerate(tags_a)}
    edges |= {(_nearest_tag(tags_a, t), k) for k, t in enumerate(tags_b)}
    prefix = {e: len(os.path.commonprefix([tags_a[e[0]], tags_b[e[1]]])) for e in edges}
    free_a, free_b = set(range(len(a))), set(range(len(b)))
    matched = []
    for i, k in sorted(edges, key=lambda e: (-prefix[e], e)):
        if prefix[(i, k)] and i in free_a and k in free_b:
            matched.append((i, k))
            free_a.discard(i)
            free_b.discard(k)
    matched += zip(sorted(free_a), sorted(free_b))
    paired_a, paired_b = {i for i, _ in matched}, {k for _, k in matched}
    return ([(a[i], b[k]) for i, k in sorted(matched)], [r for i, r in enumerate(a) if i not in paired_a],
            [r for k, r in enumerate(b) if k not in paired_b])


def _time_aligned(r: Row) -> float | None:
    return r["time_aligned_drift"]["mean"] if r.get("time_aligned_drift") else None


def _delta(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None else b - a


def _finite_or_none(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def paired_summary(a: Sequence[float], b: Sequence[float]) -> dict[str, Any]:
    """Who wins over paired values (lower is better).

    Returns:
        ``n_pairs``, ``a_better``, ``b_better``, ``ties``, ``mean_delta`` (b - a), ``spearman``
        (rank correlation of a and b; None with fewer than 2 pairs or a constant side),
        ``wilcoxon_p`` (the two-sided signed-rank test of b - a that ``tests`` also reports, from
        :func:`inspector.stats.signed_rank_test`; None when every pair ties).
    """
    from scipy import stats

    a_arr, b_arr = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    d = b_arr - a_arr
    out: dict[str, Any] = {"n_pairs": int(d.size), "a_better": int((d > TIE_TOLERANCE).sum()),
                           "b_better": int((d < -TIE_TOLERANCE).sum()),
                           "ties": int((np.abs(d) <= TIE_TOLERANCE).sum()),
                           "mean_delta": float(d.mean()) if d.size else None,
                           "spearman": None, "wilcoxon_p": None}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # constant input, small samples: reported as None
        if d.size >= 2 and np.ptp(a_arr) > 0 and np.ptp(b_arr) > 0:
            out["spearman"] = _finite_or_none(stats.spearmanr(a_arr, b_arr).statistic)
    if np.isfinite(d).any():
        p = signed_rank_test(d[np.isfinite(d)]).pvalue
        out["wilcoxon_p"] = None if p is None else _finite_or_none(p)
    return out


def compare_reports(report_a: dict[str, Any], report_b: dict[str, Any]) -> dict[str, Any]:
    """The comparison of two reports (:func:`inspector.report.build.build_report` results).

    Returns:
        ``pairs`` ({``a``, ``b`` rows, ``paired_by``, ``delta_rmse_deg``,
        ``delta_time_aligned_drift_deg``}), ``unmatched_a`` / ``unmatched_b`` (tags),
        ``summary`` (RMSE: ``n_pairs``, ``n_compared`` with an RMSE on both sides, ``a_better``,
        ``b_better``, ``ties``, ``mean_delta_rmse_deg``, ``spearman_rmse``, ``wilcoxon_p``) and
        ``time_aligned_drift`` (the same for the mean time-aligned drift, compared over pairs
        with GT joints on both sides), ``tests`` (per metric: ``metric``, ``n_pairs``,
        ``estimate``, ``ci95``, ``p``, ``test``, ``verdict``, success among them; see
        :mod:`inspector.report.significance`). Differences are b - a, in data units.
    """
    matched, unmatched_a, unmatched_b = pair_rows(report_a["rollouts"], report_b["rollouts"])
    pairs: list[dict[str, Any]] = [
        {"a": a, "b": b, "paired_by": by, "delta_rmse_deg": _delta(a["rmse_deg"], b["rmse_deg"]),
         "delta_time_aligned_drift_deg": _delta(_time_aligned(a), _time_aligned(b))}
        for a, b, by in matched]
    with_rmse = [(p["a"]["rmse_deg"], p["b"]["rmse_deg"]) for p in pairs if p["delta_rmse_deg"] is not None]
    rmse = paired_summary(*zip(*with_rmse)) if with_rmse else paired_summary([], [])
    with_drift = [(_time_aligned(p["a"]), _time_aligned(p["b"])) for p in pairs
                  if p["delta_time_aligned_drift_deg"] is not None]
    drift = paired_summary(*zip(*with_drift)) if with_drift else paired_summary([], [])
    for p in pairs:
        p["delta_video_psnr_db"] = _psnr_deltas(p["a"], p["b"])
    out: dict[str, Any] = {
        "pairs": pairs,
        "unmatched_a": [r["tag"] for r in unmatched_a],
        "unmatched_b": [r["tag"] for r in unmatched_b],
        "summary": {"n_pairs": len(pairs), "n_compared": rmse["n_pairs"], "a_better": rmse["a_better"],
                    "b_better": rmse["b_better"], "ties": rmse["ties"],
                    "mean_delta_rmse_deg": rmse["mean_delta"], "spearman_rmse": rmse["spearman"],
                    "wilcoxon_p": rmse["wilcoxon_p"]},
        "time_aligned_drift": {"n_pairs": len(pairs), "n_compared": drift["n_pairs"], "a_better": drift["a_better"],
                               "b_better": drift["b_better"], "ties": drift["ties"],
                               "mean_delta_deg": drift["mean_delta"], "spearman": drift["spearman"],
                               "wilcoxon_p": drift["wilcoxon_p"]},
    }
    out["video_psnr_db"] = _psnr_summary(pairs)
    # is each difference real, success included: one test per metric (inspector.report.significance)
    out["tests"] = metric_tests([(a, b) for a, b, _ in matched], report_a["rollouts"], report_b["rollouts"])
    errors = {side: rep["errors"] for side, rep in (("a", report_a), ("b", report_b)) if rep.get("errors")}
    if errors:
        out["errors"] = errors
    return out


def _psnr_deltas(a: Row, b: Row) -> dict[str, float]:
    """B - A mean PSNR [dB] of each view both rows have (positive: B's video is closer to GT)."""
    pa, pb = a.get("video_psnr_db") or {}, b.get("video_psnr_db") or {}
    return {v: pb[v] - pa[v] for v in sorted(pa) if v in pb}


def _psnr_summary(pairs: Sequence[Row]) -> dict[str, dict[str, Any]]:
    """Per view, over the pairs with its PSNR on both sides, who wins (higher PSNR is better:
    ``a_better`` counts pairs where A's is higher), the mean B - A [dB], Spearman, Wilcoxon p.
    This is how video-only rollouts (no RMSE, no drift) compare."""
    views = sorted({v for p in pairs for v in p["delta_video_psnr_db"]})
    out = {}
    for view in views:
        both = [(p["a"]["video_psnr_db"][view], p["b"]["video_psnr_db"][view]) for p in pairs
                if view in p["delta_video_psnr_db"]]
        a, b = zip(*both)
        s = paired_summary([-x for x in a], [-x for x in b])  # lower -PSNR is better
        out[view] = {"n_compared": s["n_pairs"], "a_better": s["a_better"], "b_better": s["b_better"],
                     "ties": s["ties"], "mean_delta_db": -s["mean_delta"] if s["mean_delta"] is not None else None,
                     "spearman": s["spearman"], "wilcoxon_p": s["wilcoxon_p"]}
    return out


def side_name(path: str | Path) -> str:
    """What a side of the comparison evaluated: ``model.name@model.checkpoint`` from the
    ``session.json`` of the session (or of the rollout's session) at ``path``, else the folder's name."""
    root = Path(path)
    if is_rollout(root) and not is_session(root) and is_session(root.parent.parent):
        root = root.parent.parent
    if is_session(root):
        try:
            meta = read_json(root / SESSION_FILE)
        except InspectorError:
            meta = None  # build_report says what is wrong with it
        model = meta.get("model") if isinstance(meta, dict) else None
        if isinstance(model, dict):
            name, checkpoint = model.get("name"), model.get("checkpoint")
            if name and checkpoint:
                return f"{name}@{checkpoint}"
            if name or checkpoint:
                return str(name or checkpoint)
    return root.resolve().name or str(path)


def build_comparison(path_a: str, path_b: str, **report_args: Any) -> dict[str, Any]:
    """Report both paths (``report_args`` as :func:`inspector.report.build.build_report` takes them)
    and compare them; ``a`` and ``b`` are the paths, ``names`` what each evaluated
    (:func:`side_name`).

    Raises:
        InspectorError: a path cannot be reported, or no rollout of A pairs with one of B.
    """
    comparison = compare_reports(build_report([path_a], **report_args), build_report([path_b], **report_args))
    if not comparison["pairs"]:
        raise InspectorError(path_b, f"no rollout pairs with one of {path_a} (pairing by tag, else by "
                                     "episode, start frame, prompt and kind)")
    return {"a": str(path_a), "b": str(path_b), "names": {"a": side_name(path_a), "b": side_name(path_b)},
            **comparison}


# ----------------------------------------------------------------------------------------------
# Text


def _f(value: float | None, fmt: str = ".3f") -> str:
    return "-" if value is None else format(value, fmt)


def _winner(delta: float | None) -> str:
    if delta is None:
        return "-"
    return "tie" if abs(delta) <= TIE_TOLERANCE else ("A" if delta > 0 else "B")


def _summary_line(name: str, s: dict[str, Any], mean_key: str, spearman_key: str) -> str:
    if not s["n_compared"]:
        return f"{name}: no pair with values on both sides"
    return (f"{name} over {s['n_compared']} pair(s): A better {s['a_better']}, B better {s['b_better']}, "
            f"ties {s['ties']}; mean delta (B - A) {s[mean_key]:+.3f}; Spearman {_f(s[spearman_key], '.3f')}")


def format_comparison(c: dict[str, Any]) -> str:
    """A short table: the pairs (the largest differences first when there are many) and the summary."""
    pairs = c["pairs"]
    shown = pairs
    if len(pairs) > MAX_TEXT_PAIRS:
        shown = sorted(pairs, key=lambda p: -abs(p["delta_rmse_deg"] or 0.0))[:MAX_TEXT_PAIRS]
    width = max([8] + [len(_pair_name(p)) for p in shown])
    names = c.get("names") or {}
    lines = [*(f"{side.upper()}: {names[side]} ({c[side]})" if side in names else f"{side.upper()}: {c[side]}"
               for side in ("a", "b")), "",
             f"{'rollout':<{width}} {'RMSE A':>8} {'RMSE B':>8} {'delta':>8} {'drift A':>8} {'drift B':>8} "
             f"{'delta':>8}  better"]
    for p in shown:
        a, b = p["a"], p["b"]
        lines.append(f"{_pair_name(p):<{width}} {_f(a['rmse_deg']):>8} {_f(b['rmse_deg']):>8} "
                     f"{_f(p['delta_rmse_deg'], '+.3f'):>8} {_f(_time_aligned(a), '.2f'):>8} "
                     f"{_f(_time_aligned(b), '.2f'):>8} {_f(p['delta_time_aligned_drift_deg'], '+.2f'):>8}  "
                     f"{_winner(p['delta_rmse_deg'] if p['delta_rmse_deg'] is not None else p['delta_time_aligned_drift_deg'])}")
    if len(shown) < len(pairs):
        lines.append(f"({len(shown)} of {len(pairs)} pairs shown, the largest RMSE differences; --json for all)")
    lines += ["", "RMSE and drift [deg]: lower is better; delta = B - A; drift: time-aligned, mean over "
                  "in-episode steps",
              _summary_line("RMSE", c["summary"], "mean_delta_rmse_deg", "spearman_rmse"),
              _summary_line("Time-aligned drift", c["time_aligned_drift"], "mean_delta_deg", "spearman")]
    for view, v in c.get("video_psnr_db", {}).items():
        lines.append(f"PSNR {view} over {v['n_compared']} pair(s) (higher is better): A better {v['a_better']}, "
                     f"B better {v['b_better']}, ties {v['ties']}; mean delta (B - A) {v['mean_delta_db'] + 0.0:+.2f} dB")
    for side in ("a", "b"):
        tags = c[f"unmatched_{side}"]
        if tags:
            more = f" ... ({len(tags)})" if len(tags) > 8 else ""
            lines.append(f"Unpaired in {side.upper()}: {', '.join(tags[:8])}{more}")
    for side, errors in c.get("errors", {}).items():
        for err in errors.values():
            lines.append(f"error ({side.upper()}): {err}")
    lines += verdict_lines(c.get("tests", []))
    return "\n".join(lines)


def _pair_name(p: dict[str, Any]) -> str:
    a, b = p["a"]["tag"], p["b"]["tag"]
    return a if a == b else f"{a} ~ {b}"
