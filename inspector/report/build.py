"""``inspector report``: drift metrics per rollout and over the set, as tables or JSON.

The work streams: rollouts are read by worker processes (``--jobs``, default one per core) a task
at a time (:mod:`inspector.rows.tasks`) and only their summary rows come back, so memory
follows a task, not the evaluation. Rows are kept in the metrics cache (:mod:`inspector.cache`):
a second report on unchanged rollouts reads them instead of decoding videos again.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..analysis.latents import latents_summary
from ..analysis.measure_settings import DEFAULT_MEASURES, MeasureSettings
from ..analysis.video_action import median_lag_label
from ..data.episodes import episode_tag
from ..data.lerobot_dataset import dataset_name
from ..data.session import CHAINED_KINDS
from ..data.sources import open_sources
from ..errors import InspectorError
from ..jobs.pool import default_jobs, worker_count
from ..jobs.ray import ray_workers
from ..progress import warn_once
from ..rows.outcomes import attach_outcomes
from ..rows.rollout import aggregate, limit_margin, limit_steps, prompt_divergence_record, prompt_pairs
from ..rows.tasks import EpisodeTask, Task, plan_episode_tasks, plan_tasks, run_tasks, run_tasks_on_ray
from ..units import DEFAULT_LIMIT_MARGIN_DEG, JOINT_NAMES
from .outcomes import outcome_lines, success_lines
from .repository_figures import attach_source_facts, repository_lines
from .sanity_text import sanity_lines
from .trajectories import TRAJECTORY_LAYOUT, trajectory_table

# Row fields a report sets on each row after the metrics cache (a cached row lacks them): outcomes
# (a label changes without the rollout changing) and what the rollout's source says of it.
FIELDS_SET_AFTER_CACHE = ("outcome_sources", "task_outcome", "distribution_source", "dataset", "repository_figures")

CHAINED_TITLES = {
    "autoregressive": "Autoregressive rollouts (drift in data units; post-episode samples excluded)",
    "open_loop_replay": "Open-loop replays (each chunk from the real observation at its start; drift in data "
                        "units; post-episode samples excluded)",
}


def build_report(paths: Sequence[str], dataset: str | None = None, jobs: int | None = None,
                 use_cache: bool = True, limit_margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG,
                 cache_dir: str | None = None, progress: bool | None = None,
                 ray: str | None = None, calibration: str | None = None,
                 outcome_source: str | None = None,
                 measures: MeasureSettings = DEFAULT_MEASURES) -> dict[str, Any]:
    """Metrics for every rollout under ``paths`` (and every episode of the LeRobot datasets among
    them); what could not be read is listed under ``errors``.

    Args:
        paths: sessions, rollout directories, DreamZero-SO101 output directories or LeRobot
            datasets (a directory, or ``org/name`` in the local LeRobot cache).
        dataset: a LeRobot dataset with the GT episodes, for sessions that name none.
        jobs: worker processes (default: one per core; 1 computes in this process).
        use_cache: read and write the metrics cache.
        limit_margin_deg: tolerance past a joint limit before it counts as a violation [deg].
        cache_dir: the metrics cache directory (default: the user's cache directory).
        progress: a progress bar on stderr (default: when stderr is a terminal).
        ray: run the tasks on Ray at this address instead (``local``, ``auto``, ``HOST:PORT``,
            ``ray://HOST:PORT``; see :mod:`inspector.jobs.ray`); ``jobs`` is then a local
            instance's CPUs, or a cluster's tasks at once (default: no limit).
        calibration: a GR00T-Dreams dump's calibration (``--calibration``; None: its default).
        outcome_source: the outcome source tables use (``--outcome-source``; None: the precedence
            rule of :func:`inspector.outcomes.effective_outcome`).
        measures: the sanity measures' tolerances (completion's, the seam flag's).

    Returns:
        ``{"rollouts", "aggregate", "prompt_divergence"?, "episodes"?, "neural_trajectories"?,
        "warnings"?, "errors"?}``.

    Raises:
        InspectorError: a path is unusable, or nothing under ``paths`` could be reported (none
            at all, or every one broken: the first one's error, counting the others), or
            ``ray`` cannot be used.
    """
    ray_jobs = jobs
    cores = default_jobs()
    if ray is None:  # tasks are cut for the workers that will run them: one per core at most (worker_count)
        planned = min(jobs or cores, cores)
    else:
        planned = cores if jobs is None else max(1, jobs)
    # arrays are read by the workers; datasets are reported episode by episode
    sources = open_sources(paths, dataset=dataset, lazy=True, datasets=True, calibration=calibration)
    try:
        names = {str(s.root): s.name for s in sources.sessions}
        names.update({str(d.root): dataset_name(d) for d in sources.datasets})
        failed = [err for s in sources.sessions for _, err in sorted(s.errors.items())]
        errors = {f"{s.name}/{tag}": str(err) for s in sources.sessions for tag, err in s.errors.items()}
        order = {(str(s.root), tag): i for i, (s, tag) in enumerate(
            (s, tag) for s in sources.sessions for tag in sorted(s.rollouts))}
        order.update({(str(d.root), episode_tag(e.index)): len(order) + i for i, (d, e) in enumerate(
            (d, e) for d in sources.datasets for e in d.episodes)})
        tasks: list[Task | EpisodeTask] = [*plan_tasks(sources.sessions, planned, limit_margin_deg, cache_dir, use_cache,
                                                                      measures),
                                           *plan_episode_tasks(sources.datasets, planned, limit_margin_deg)]
        rows: dict[tuple[str, str], dict[str, Any]] = {}
        bar = _progress_bar(len(order), progress)
        n_cached = 0
        running = run_tasks(tasks, worker_count(jobs, len(tasks))) if ray is None else _on_ray(tasks, ray, ray_jobs)
        for outcomes in running:
            for o in outcomes:
                warn_once(o.cache_warning)
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
            print(f"inspector: {len(rows)} reported ({n_cached} from the metrics cache)"
                  + (f", {len(errors)} with errors" if errors else ""), file=sys.stderr)
        if not rows:
            if not failed:
                where = (", ".join([*(str(s.root) for s in sources.sessions), *(str(d.root) for d in sources.datasets)])
                         or ", ".join(map(str, paths)))
                raise InspectorError(where, "no rollouts to report")
            more = f" ({len(failed) - 1} more broken rollout(s))" if len(failed) > 1 else ""
            raise InspectorError(failed[0].file, failed[0].what + more)
        # FIELDS_SET_AFTER_CACHE, on every row, cached or not
        outcome_warnings = attach_outcomes(sources, rows, outcome_source)  # after the cache: labels change
        source_notes = attach_source_facts(sources, rows)  # after the cache too: the source's files change
        keys = sorted(rows, key=order.__getitem__)
        dataset_roots = {str(d.root) for d in sources.datasets}
        session_keys = [k for k in keys if k[0] not in dataset_roots]
        ordered = [rows[k] for k in session_keys]
        report: dict[str, Any] = {"rollouts": ordered, "aggregate": aggregate(ordered)}
        divergences = _prompt_divergences(sources, session_keys, rows)
        if divergences:
            report["prompt_divergence"] = divergences
        report["latents"] = _latents(sources, session_keys, rows)
        episodes = [rows[k] for k in keys if k[0] in dataset_roots]
        trajectories = [e for e in episodes if e.get("layout") == TRAJECTORY_LAYOUT]
        if trajectories:
            report["neural_trajectories"] = trajectories
            episodes = [e for e in episodes if e.get("layout") != TRAJECTORY_LAYOUT]
        if episodes:
            report["episodes"] = episodes
        warnings = ([f"{r['tag']}: {r['gt_warning']}" for r in ordered if r.get("gt_warning")] + outcome_warnings
                    + source_notes + _camera_warnings(sources))
        if warnings:
            report["warnings"] = warnings
        if errors:
            report["errors"] = errors
        return report
    finally:
        sources.close()


def _on_ray(tasks, address: str, jobs: int | None):
    with ray_workers(address, jobs) as workers:
        yield from run_tasks_on_ray(workers, tasks)


def _prompt_divergences(sources, keys: list[tuple[str, str]], rows: dict) -> list[dict[str, Any]]:
    """Training vs novel prompt (and any other prompt pairs) from the same start."""
    sessions = {str(s.root): s for s in sources.sessions}
    entries = [(key, (key[0], rows[key]["episode_index"], rows[key]["start_frame"]), key[1], rows[key]["prompt"])
               for key in keys if rows[key]["kind"] == "autoregressive" and not rows[key].get("video_only")]
    out = []
    for (root_a, tag_a), (root_b, tag_b) in prompt_pairs(entries):
        a, b = sessions[root_a].rollouts[tag_a], sessions[root_b].rollouts[tag_b]
        out.append(prompt_divergence_record(a, b))
        a.release_arrays()
        b.release_arrays()
    return out


def _latents(sources, keys: list[tuple[str, str]], rows: dict) -> dict[str, Any] | None:
    """PCA and episode silhouette of the rollouts' latents (None when none has any)."""
    sessions = {str(s.root): s for s in sources.sessions}
    entries = []
    for root, tag in keys:
        if rows[(root, tag)].get("latents") is None:
            continue
        rollout = sessions[root].rollouts[tag]
        entries.append((tag, rows[(root, tag)]["episode_index"], rollout.latents))
        rollout.release_arrays()
    return latents_summary(entries)


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
    lines: list[str] = _episode_table(report.get("episodes", [])) + trajectory_table(report.get("neural_trajectories", []))
    evaluated = [r for r in rows if r.get("outcome")]
    single = [r for r in rows if r["kind"] == "single_chunk" and not r.get("outcome")]
    chained = {kind: [r for r in rows if r["kind"] == kind] for kind in CHAINED_KINDS}
    views = sorted({v for r in rows for v in r["video_psnr_db"]})
    psnr_head = "".join(f" {'PSNR ' + v:>11}" for v in views)
    width = max([18] + [len(r["tag"]) for r in rows])

    psnr_head += "".join(f" {'lag s ' + v:>11}" for v in views)

    def psnr_cells(r: dict[str, Any]) -> str:
        lag = r.get("video_action") or {}
        return ("".join(f" {_f(r['video_psnr_db'].get(v), '.1f'):>11}" for v in views)
                + "".join(f" {median_lag_label(lag.get(v)):>11}" for v in views))

    if single:
        lines += ["Single-chunk predictions (each chunk's horizon vs logged GT)",
                  f"{'rollout':<{width}} {'RMSE deg':>9} {'worst joint (RMSE)':>20} {'step0 MSE':>10} "
                  f"{'last MSE':>9} {'lim.steps':>9}{psnr_head}  prompt"]
        for r in single:
            worst = _worst_joint(r["per_joint_rmse"])
            mse = r["per_step_mse"]
            lines.append(f"{r['tag']:<{width}} {_f(r['rmse_deg'], '.3f'):>9} {worst:>20} "
                         f"{_f(mse[0] if mse else None):>10} {_f(mse[-1] if mse else None):>9} "
                         f"{_f(limit_steps(r), 'd'):>9}{psnr_cells(r)}  {r['prompt']}")
        lines.append("")
    lines += _evaluated_table(evaluated, views)
    lines += outcome_lines(rows)
    lines += success_lines(report["aggregate"])
    for kind, auto in chained.items():
        if not auto:
            continue
        lines += [CHAINED_TITLES[kind],
                  f"{'rollout':<{width}} {'chunks':>6} {'time-al.':>9} {'final':>8} {'best-m.':>8} {'DTW':>7} "
                  f"{'tempo':>6} {'EE mm':>7} {'post':>5} {'lim.steps':>9}{psnr_head}  prompt"]
        for r in auto:
            ta, bm, dtw = r["time_aligned_drift"], r["best_match_drift"], r["dtw_drift"]
            lines.append(
                f"{r['tag']:<{width}} {r['n_chunks']:>6} {_f(ta and ta['mean']):>9} {_f(ta and ta['final']):>8} "
                f"{_f(bm and bm['mean']):>8} {_f(dtw and dtw['mean']):>7} {_f(r['tempo']):>6} "
                f"{_f(r['ee_error_mm'] and r['ee_error_mm']['mean'], '.1f'):>7} "
                f"{_f(r['post_episode_chunks'], 'd'):>5} {_f(limit_steps(r), 'd'):>9}{psnr_cells(r)}"
                f"  {r['prompt']}")
        if any(r["time_aligned_drift"] is None for r in auto):
            lines.append("  ('-': no GT joints; import with --dataset ROOT to measure drift)")
        lines.append("")
    lines += repository_lines(rows)
    for warning in report.get("warnings", []):
        lines.append(f"warning: {warning}")
    for err in report.get("errors", {}).values():
        lines.append(f"error: {err}")
    if not rows:
        return "\n".join(lines)
    margin = limit_margin(rows)
    lines.append(f"lim.steps: steps with any joint more than {_f(margin, 'g')} deg past its URDF limit "
                 f"('-': video only, no joints); "
                 f"PSNR [dB]: imagined vs GT frames of that camera; lag s: median of the video's GT time "
                 f"minus the joints' (+: the video runs ahead of the actions; frozen: the video stands still "
                 f"while the joints move, no lag; no match: no frame has a GT time on both sides)")
    agg = report["aggregate"]
    psnr = ", ".join(f"{v} {m:.2f}" for v, m in agg["mean_video_psnr_db"].items()) or "-"
    lines.append(f"Aggregate over {agg['n']} rollouts: RMSE mean {_f(agg['mean_rmse_deg'], '.3f')}, "
                 f"median {_f(agg['median_rmse_deg'], '.3f')}, best {_f(agg['best_rmse_deg'], '.3f')}, "
                 f"worst {_f(agg['worst_rmse_deg'], '.3f')} deg; mean PSNR per view [dB]: {psnr}")
    for p in report.get("prompt_divergence", []):
        collapse = "never" if p["collapse_chunk"] is None else f"from chunk {p['collapse_chunk']}"
        lines.append(f"Prompt divergence {p['a']} vs {p['b']}: mean {p['mean']:.2f}, max {p['max']:.2f}; "
                     f"paths indistinguishable {collapse}")
    lines += sanity_lines(report)
    return "\n".join(lines)


def _episode_table(episodes: list[dict[str, Any]]) -> list[str]:
    """Dataset episodes: how well the follower tracked its command, and limits (triage)."""
    if not episodes:
        return []
    width = max(12, *(len(str(e["dataset"])) for e in episodes))
    lines = ["Dataset episodes (tracking error = |commanded action - measured state|, L2 over 6 joints)",
             f"{'dataset':<{width}} {'ep':>5} {'frames':>6} {'track mean':>10} {'max':>7} "
             f"{'worst joint (RMSE)':>20} {'EE mm':>6} {'lim.steps meas/cmd':>18}  task"]
    for e in episodes:
        te = e["tracking_error"]
        worst = _worst_joint(te["rmse"])
        lim = e["limit_violations"]
        lines.append(f"{e['dataset']:<{width}} {e['episode_index']:>5} {e['length']:>6} {te['l2_mean']:>10.2f} "
                     f"{te['l2_max']:>7.2f} {worst:>20} {e['ee_tracking_error_mm']['mean']:>6.1f} "
                     f"{str(lim['measured']['steps']) + ' / ' + str(lim['commanded']['steps']):>18}  {e['task']}")
    lines.append("")
    return lines


def _evaluated_table(rows: list[dict[str, Any]], views: list[str]) -> list[str]:
    """Episodes of a simulated evaluation: success, reward, how closely the arm followed its
    commands (``-`` for a video-only episode), PSNR per view (the success rate per task follows,
    with the other outcomes')."""
    if not rows:
        return []
    width = max([18] + [len(r["tag"]) for r in rows])
    psnr_head = "".join(f" {('PSNR ' + v)[:11]:>11}" for v in views)
    lines = ["Evaluated episodes (tracking = commanded action vs executed state)",
             f"{'episode':<{width}} {'success':>7} {'reward':>8} {'max rew.':>8} {'steps':>6} {'RMSE deg':>9} "
             f"{'lim.steps':>9}{psnr_head}  task"]
    for r in rows:
        o = r["outcome"]
        psnr = "".join(f" {_f(r['video_psnr_db'].get(v), '.1f'):>11}" for v in views)
        lines.append(f"{r['tag']:<{width}} {'yes' if o.get('success') else 'no':>7} {_f(o.get('sum_reward'), '.3g'):>8} "
                     f"{_f(o.get('max_reward'), '.3g'):>8} {r['steps_per_chunk']:>6} {_f(r['rmse_deg'], '.3f'):>9} "
                     f"{_f(limit_steps(r), 'd'):>9}{psnr}  {o.get('task')}")
    lines.append("")
    return lines


def _worst_joint(per_joint_rmse: list[float] | None) -> str:
    """``"<joint> <rmse>"`` of the joint with the largest RMSE, or ``-``."""
    if per_joint_rmse is None:
        return "-"
    k = int(np.argmax(per_joint_rmse))
    return f"{JOINT_NAMES[k]} {per_joint_rmse[k]:.2f}"


def _camera_warnings(sources: Any) -> list[str]:
    """A session's ``cameras.json`` that cannot be read, said once (its rows carry the same note
    on each view's camera measures, left unmeasured; the rest of the report goes on)."""
    from ..data.cameras import session_cameras

    out = []
    for session in sources.sessions:
        try:
            session_cameras(session)
        except InspectorError as exc:
            out.append(f"cameras not read, the arms-in-frames measures left out: {exc}")
    return out
