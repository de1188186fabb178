"""``inspector report``: drift metrics per rollout and over the set, as tables or JSON."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from . import metrics
from .sources import open_sources
from .timeline import RolloutTimeline, build_timeline
from .units import JOINT_NAMES


def _in_episode(tl: RolloutTimeline, series: np.ndarray) -> np.ndarray:
    """The samples of a (T,) series before the real episode's end (all of them if none are)."""
    inside = series if tl.post_episode is None else series[~tl.post_episode]
    return inside if inside.size else series


def _drift_summary(tl: RolloutTimeline, series: np.ndarray | None) -> dict[str, Any] | None:
    """mean / final over in-episode samples, plus the per-chunk means (all samples)."""
    if series is None:
        return None
    inside = _in_episode(tl, series)
    per_chunk = tl.per_chunk(series)
    return {"mean": float(inside.mean()), "final": float(inside[-1]),
            "per_chunk": [round(float(v), 6) for v in per_chunk]}


def rollout_summary(tl: RolloutTimeline) -> dict[str, Any]:
    """The JSON record of one rollout (fields needing GT joints are null without them)."""
    r = tl.rollout
    ce = tl.chunk_errors
    post_chunks = None
    if tl.episode_end_step is not None:
        post_chunks = int((tl.chunk_start_step >= tl.episode_end_step).sum())
    elif tl.has_gt_joints or tl.gt.episode_length is not None:
        post_chunks = 0
    ee = None
    if tl.ee_error_mm is not None:
        inside = _in_episode(tl, tl.ee_error_mm)
        ee = {"mean": float(inside.mean()), "final": float(inside[-1])}
    psnr = {view: vm.mean_psnr_db for view, vm in tl.all_video_metrics().items()
            if vm.mean_psnr_db is not None}
    by_joint = tl.limit_violation.sum(axis=0)
    return {
        "tag": r.tag,
        "session": r.session.name if r.session is not None else None,
        "kind": r.kind,
        "prompt": r.prompt,
        "episode_index": r.episode_index,
        "units": tl.units.label(),
        "rmse_deg": ce.rmse if ce is not None else None,
        "per_joint_rmse": ce.per_joint_rmse.tolist() if ce is not None else None,
        "per_step_mse": ce.per_step_mse.tolist() if ce is not None else None,
        "time_aligned_drift": _drift_summary(tl, tl.time_aligned_drift),
        "best_match_drift": _drift_summary(tl, tl.best_match_drift),
        "dtw_drift": _drift_summary(tl, tl.dtw_drift),
        "tempo": tl.tempo,
        "ee_error_mm": ee,
        "limit_violations": {"count": int(by_joint.sum()),
                             "by_joint": {j: int(c) for j, c in zip(JOINT_NAMES, by_joint)}},
        "video_psnr_db": psnr,
        "post_episode_chunks": post_chunks,
        "gt_source": tl.gt.source,
    }


def build_report(paths: Sequence[str], dataset: str | None = None) -> dict[str, Any]:
    """Metrics for every rollout under ``paths``; broken rollouts are listed under ``errors``.

    Raises:
        InspectorError: a path is unusable, or no rollout under ``paths`` could be reported (none
            at all, or every one broken: the first one's error, counting the others).
    """
    sources = open_sources(paths, dataset=dataset)
    try:
        rows: list[dict[str, Any]] = []
        timelines: list[RolloutTimeline] = []
        failed = [err for s in sources.sessions for _, err in sorted(s.errors.items())]
        errors = {f"{s.name}/{tag}": str(err) for s in sources.sessions for tag, err in s.errors.items()}
        from .errors import InspectorError

        for session, rollout in sources.rollouts():
            try:
                tl = build_timeline(rollout)
                rows.append(rollout_summary(tl))
                timelines.append(tl)
            except InspectorError as exc:
                errors[f"{session.name}/{rollout.tag}"] = str(exc)
                failed.append(exc)
        if not rows:
            if not failed:
                where = ", ".join(str(s.root) for s in sources.sessions) or ", ".join(map(str, paths))
                raise InspectorError(where, "no rollouts to report")
            more = f" ({len(failed) - 1} more broken rollout(s))" if len(failed) > 1 else ""
            raise InspectorError(failed[0].file, failed[0].what + more)
        report: dict[str, Any] = {"rollouts": rows, "aggregate": _aggregate(rows)}
        divergences = _prompt_pairs(timelines)
        if divergences:
            report["prompt_divergence"] = divergences
        if errors:
            report["errors"] = errors
        return report
    finally:
        sources.close()


def _aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    rmse = metrics.aggregate([r["rmse_deg"] for r in rows if r["rmse_deg"] is not None])
    psnr = [v for r in rows for v in r["video_psnr_db"].values()]
    return {
        "n": len(rows),
        "mean_rmse_deg": rmse["mean"],
        "median_rmse_deg": rmse["median"],
        "best_rmse_deg": rmse["best"],
        "worst_rmse_deg": rmse["worst"],
        "mean_video_psnr_db": float(np.mean(psnr)) if psnr else None,
    }


def _prompt_pairs(timelines: list[RolloutTimeline]) -> list[dict[str, Any]]:
    """Autoregressive rollouts of one session and episode with different prompts, compared pairwise."""
    out = []
    auto = [t for t in timelines if t.kind == "autoregressive"]
    for i, a in enumerate(auto):
        for b in auto[i + 1:]:
            ra, rb = a.rollout, b.rollout
            same_start = (ra.session is rb.session and ra.episode_index == rb.episode_index
                          and ra.start_frame == rb.start_frame)
            if not same_start or ra.prompt == rb.prompt:
                continue
            _, per_chunk, collapse = metrics.prompt_divergence(a.pred, b.pred, a.executed_per_chunk)
            out.append({"a": ra.tag, "b": rb.tag, "prompt_a": ra.prompt, "prompt_b": rb.prompt,
                        "mean": float(per_chunk.mean()), "max": float(per_chunk.max()),
                        "per_chunk": [round(float(v), 6) for v in per_chunk],
                        "collapse_chunk": collapse})
    return out


# ----------------------------------------------------------------------------------------------
# Text tables


def _f(value: Any, fmt: str = ".2f") -> str:
    return "-" if value is None else format(value, fmt)


def format_report(report: dict[str, Any]) -> str:
    """Readable tables: single-chunk rollouts, autoregressive drift, aggregate, prompt pairs."""
    rows = report["rollouts"]
    lines: list[str] = []
    single = [r for r in rows if r["kind"] == "single_chunk"]
    auto = [r for r in rows if r["kind"] == "autoregressive"]
    if single:
        lines += ["Single-chunk predictions (24 actions vs logged GT)",
                  f"{'rollout':<18} {'RMSE deg':>9} {'worst joint':>16} {'step0 MSE':>10} {'last MSE':>9} "
                  f"{'limits':>6} {'PSNR dB':>8}  prompt"]
        for r in single:
            worst = "-"
            if r["per_joint_rmse"] is not None:
                k = int(np.argmax(r["per_joint_rmse"]))
                worst = f"{JOINT_NAMES[k]} {r['per_joint_rmse'][k]:.2f}"
            psnr = r["video_psnr_db"].get("front", next(iter(r["video_psnr_db"].values()), None))
            mse = r["per_step_mse"]
            lines.append(f"{r['tag']:<18} {_f(r['rmse_deg'], '.3f'):>9} {worst:>16} "
                         f"{_f(mse[0] if mse else None):>10} {_f(mse[-1] if mse else None):>9} "
                         f"{r['limit_violations']['count']:>6} {_f(psnr):>8}  {r['prompt']}")
        lines.append("")
    if auto:
        lines += ["Autoregressive rollouts (drift in data units; post-episode samples excluded)",
                  f"{'rollout':<18} {'chunks':>6} {'time-al.':>9} {'final':>8} {'best-m.':>8} {'DTW':>7} "
                  f"{'tempo':>6} {'EE mm':>7} {'post':>5} {'limits':>6} {'PSNR':>6}  prompt"]
        for r in auto:
            ta, bm, dtw = r["time_aligned_drift"], r["best_match_drift"], r["dtw_drift"]
            n = len(ta["per_chunk"]) if ta else "-"
            psnr = r["video_psnr_db"]
            lines.append(
                f"{r['tag']:<18} {n:>6} {_f(ta and ta['mean']):>9} {_f(ta and ta['final']):>8} "
                f"{_f(bm and bm['mean']):>8} {_f(dtw and dtw['mean']):>7} {_f(r['tempo']):>6} "
                f"{_f(r['ee_error_mm'] and r['ee_error_mm']['mean'], '.1f'):>7} "
                f"{_f(r['post_episode_chunks'], 'd'):>5} {r['limit_violations']['count']:>6} "
                f"{_f(np.mean(list(psnr.values())) if psnr else None, '.1f'):>6}  {r['prompt']}")
        if any(r["time_aligned_drift"] is None for r in auto):
            lines.append("  ('-': no GT joints; import with --dataset ROOT to measure drift)")
        lines.append("")
    agg = report["aggregate"]
    lines.append(f"Aggregate over {agg['n']} rollouts: RMSE mean {_f(agg['mean_rmse_deg'], '.3f')}, "
                 f"median {_f(agg['median_rmse_deg'], '.3f')}, best {_f(agg['best_rmse_deg'], '.3f')}, "
                 f"worst {_f(agg['worst_rmse_deg'], '.3f')} deg; mean PSNR {_f(agg['mean_video_psnr_db'])} dB")
    for p in report.get("prompt_divergence", []):
        collapse = "never" if p["collapse_chunk"] is None else f"from chunk {p['collapse_chunk']}"
        lines.append(f"Prompt divergence {p['a']} vs {p['b']}: mean {p['mean']:.2f}, max {p['max']:.2f}; "
                     f"paths indistinguishable {collapse}")
    for tag, err in report.get("errors", {}).items():
        lines.append(f"error: {err}")
    return "\n".join(lines)
