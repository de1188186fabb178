"""``inspector report``: drift metrics per rollout and over the set, as tables or JSON.

The work streams: rollouts are read by worker processes (``--jobs``, default one per core) a task
at a time (:mod:`inspector.report_jobs`) and only their summary rows come back, so memory
follows a task, not the evaluation. Rows are kept in the metrics cache (:mod:`inspector.cache`):
a second report on unchanged rollouts reads them instead of decoding videos again.
"""

from __future__ import annotations

import sys
from typing import Any, Sequence

import numpy as np

from .errors import InspectorError
from .report_jobs import default_jobs, plan_tasks, run_tasks
from .report_row import aggregate, prompt_divergence_record, prompt_pairs
from .sources import open_sources
from .units import DEFAULT_LIMIT_MARGIN_DEG, JOINT_NAMES


def build_report(paths: Sequence[str], dataset: str | None = None, jobs: int | None = None,
                 use_cache: bool = True, limit_margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG,
                 cache_dir: str | None = None, progress: bool | None = None,
                 ray: str | None = None) -> dict[str, Any]:
    """Metrics for every rollout under ``paths``; broken rollouts are listed under ``errors``.

    Args:
        paths: sessions, rollout directories or DreamZero-SO101 output directories.
        dataset: a LeRobot dataset with the GT episodes, for sessions that name none.
        jobs: worker processes (default: one per core; 1 computes in this process).
        use_cache: read and write the metrics cache.
        limit_margin_deg: tolerance past a joint limit before it counts as a violation [deg].
        cache_dir: the metrics cache directory (default: the user's cache directory).
        progress: a progress bar on stderr (default: when stderr is a terminal).
        ray: run the tasks on Ray at this address instead (``local``, ``auto``, ``HOST:PORT``,
            ``ray://HOST:PORT``; see :mod:`inspector.ray_jobs`); ``jobs`` is then a local
            instance's CPUs, or a cluster's tasks at once (default: no limit).

    Raises:
        InspectorError: a path is unusable, or no rollout under ``paths`` could be reported (none
            at all, or every one broken: the first one's error, counting the others), or
            ``ray`` cannot be used.
    """
    ray_jobs = jobs
    jobs = default_jobs() if jobs is None else max(1, jobs)
    sources = open_sources(paths, dataset=dataset, lazy=True)  # arrays are read by the workers
    try:
        names = {str(s.root): s.name for s in sources.sessions}
        failed = [err for s in sources.sessions for _, err in sorted(s.errors.items())]
        errors = {f"{s.name}/{tag}": str(err) for s in sources.sessions for tag, err in s.errors.items()}
        order = {(str(s.root), tag): i for i, (s, tag) in enumerate(
            (s, tag) for s in sources.sessions for tag in sorted(s.rollouts))}
        tasks = plan_tasks(sources.sessions, jobs, limit_margin_deg, cache_dir, use_cache)
        rows: dict[tuple[str, str], dict[str, Any]] = {}
        bar = _progress_bar(len(order), progress)
        n_cached = 0
        for outcomes in run_tasks(tasks, jobs) if ray is None else _on_ray(tasks, ray, ray_jobs):
            for o in outcomes:
                if o.row is not None:
                    rows[(o.session_root, o.tag)] = o.row
                    n_cached += o.cached
                else:
                    err = InspectorError(o.error_file or o.tag, o.error or "failed")
                    errors[f"{names[o.session_root]}/{o.tag}"] = str(err)
                    failed.append(err)
            if bar is not None:
                bar.update(len(outcomes))
        if bar is not None:
            bar.close()
            print(f"inspector: {len(rows)} rollout(s) reported ({n_cached} from the metrics cache)"
                  + (f", {len(errors)} with errors" if errors else ""), file=sys.stderr)
        if not rows:
            if not failed:
                where = ", ".join(str(s.root) for s in sources.sessions) or ", ".join(map(str, paths))
                raise InspectorError(where, "no rollouts to report")
            more = f" ({len(failed) - 1} more broken rollout(s))" if len(failed) > 1 else ""
            raise InspectorError(failed[0].file, failed[0].what + more)
        keys = sorted(rows, key=order.__getitem__)
        ordered = [rows[k] for k in keys]
        report: dict[str, Any] = {"rollouts": ordered, "aggregate": aggregate(ordered)}
        divergences = _prompt_divergences(sources, keys, rows)
        if divergences:
            report["prompt_divergence"] = divergences
        if errors:
            report["errors"] = errors
        return report
    finally:
        sources.close()


def _on_ray(tasks, address: str, jobs: int | None):
    from .ray_jobs import ray_workers

    with ray_workers(address, jobs) as workers:
        yield from workers.run_tasks(tasks)


def _prompt_divergences(sources, keys: list[tuple[str, str]], rows: dict) -> list[dict[str, Any]]:
    """Training vs novel prompt (and any other prompt pairs) from the same start."""
    sessions = {str(s.root): s for s in sources.sessions}
    entries = [(key, (key[0], rows[key]["episode_index"], rows[key]["start_frame"]), key[1], rows[key]["prompt"])
               for key in keys if rows[key]["kind"] == "autoregressive"]
    out = []
    for (root_a, tag_a), (root_b, tag_b) in prompt_pairs(entries):
        a, b = sessions[root_a].rollouts[tag_a], sessions[root_b].rollouts[tag_b]
        out.append(prompt_divergence_record(a, b))
        a.release_arrays()
        b.release_arrays()
    return out


def _progress_bar(total: int, show: bool | None):
    """A tqdm bar on stderr (by default only when stderr is a terminal)."""
    if show is None:
        show = sys.stderr.isatty()
    if not show or total == 0:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="rollout", desc="report", file=sys.stderr, leave=False)


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
    views = sorted({v for r in rows for v in r["video_psnr_db"]})
    psnr_head = "".join(f" {'PSNR ' + v:>11}" for v in views)
    width = max([18] + [len(r["tag"]) for r in rows])

    def psnr_cells(r: dict[str, Any]) -> str:
        return "".join(f" {_f(r['video_psnr_db'].get(v), '.1f'):>11}" for v in views)

    if single:
        lines += ["Single-chunk predictions (each chunk's horizon vs logged GT)",
                  f"{'rollout':<{width}} {'RMSE deg':>9} {'worst joint (RMSE)':>20} {'step0 MSE':>10} "
                  f"{'last MSE':>9} {'lim.steps':>9}{psnr_head}  prompt"]
        for r in single:
            worst = "-"
            if r["per_joint_rmse"] is not None:
                k = int(np.argmax(r["per_joint_rmse"]))
                worst = f"{JOINT_NAMES[k]} {r['per_joint_rmse'][k]:.2f}"
            mse = r["per_step_mse"]
            lines.append(f"{r['tag']:<{width}} {_f(r['rmse_deg'], '.3f'):>9} {worst:>20} "
                         f"{_f(mse[0] if mse else None):>10} {_f(mse[-1] if mse else None):>9} "
                         f"{r['limit_violations']['steps']:>9}{psnr_cells(r)}  {r['prompt']}")
        lines.append("")
    if auto:
        lines += ["Autoregressive rollouts (drift in data units; post-episode samples excluded)",
                  f"{'rollout':<{width}} {'chunks':>6} {'time-al.':>9} {'final':>8} {'best-m.':>8} {'DTW':>7} "
                  f"{'tempo':>6} {'EE mm':>7} {'post':>5} {'lim.steps':>9}{psnr_head}  prompt"]
        for r in auto:
            ta, bm, dtw = r["time_aligned_drift"], r["best_match_drift"], r["dtw_drift"]
            lines.append(
                f"{r['tag']:<{width}} {r['n_chunks']:>6} {_f(ta and ta['mean']):>9} {_f(ta and ta['final']):>8} "
                f"{_f(bm and bm['mean']):>8} {_f(dtw and dtw['mean']):>7} {_f(r['tempo']):>6} "
                f"{_f(r['ee_error_mm'] and r['ee_error_mm']['mean'], '.1f'):>7} "
                f"{_f(r['post_episode_chunks'], 'd'):>5} {r['limit_violations']['steps']:>9}{psnr_cells(r)}"
                f"  {r['prompt']}")
        if any(r["time_aligned_drift"] is None for r in auto):
            lines.append("  ('-': no GT joints; import with --dataset ROOT to measure drift)")
        lines.append("")
    margin = rows[0]["limit_violations"]["margin_deg"] if rows else DEFAULT_LIMIT_MARGIN_DEG
    lines.append(f"lim.steps: steps with any joint more than {margin:g} deg past its URDF limit; "
                 f"PSNR [dB]: imagined vs GT frames of that camera")
    agg = report["aggregate"]
    psnr = ", ".join(f"{v} {m:.2f}" for v, m in agg["mean_video_psnr_db"].items()) or "-"
    lines.append(f"Aggregate over {agg['n']} rollouts: RMSE mean {_f(agg['mean_rmse_deg'], '.3f')}, "
                 f"median {_f(agg['median_rmse_deg'], '.3f')}, best {_f(agg['best_rmse_deg'], '.3f')}, "
                 f"worst {_f(agg['worst_rmse_deg'], '.3f')} deg; mean PSNR per view [dB]: {psnr}")
    for p in report.get("prompt_divergence", []):
        collapse = "never" if p["collapse_chunk"] is None else f"from chunk {p['collapse_chunk']}"
        lines.append(f"Prompt divergence {p['a']} vs {p['b']}: mean {p['mean']:.2f}, max {p['max']:.2f}; "
                     f"paths indistinguishable {collapse}")
    for tag, err in report.get("errors", {}).items():
        lines.append(f"error: {err}")
    return "\n".join(lines)
