"""``inspector export``, the command: what a PATH and ``-o`` mean, one recording written here or
many by worker processes (:mod:`inspector.export.jobs`), and the lines it prints.

The recording itself is :mod:`inspector.export.recording`'s.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from ..analysis.measure_settings import DEFAULT_MEASURES, MeasureSettings
from ..cache import MetricsCache
from ..data.episodes import episode_rollout
from ..data.lerobot_dataset import dataset_name
from ..data.sources import open_sources
from ..errors import InspectorError
from ..jobs.pool import worker_count
from ..progress import FractionBar
from ..units import DEFAULT_LIMIT_MARGIN_DEG
from .files import RRD_SUFFIX, format_size
from .jobs import export_in_processes, export_on_ray


def export_cli(path: str | Path, output: str | Path, rollout: str | None = None,
               views: Sequence[str] | None = None, dataset: str | Path | None = None,
               use_cache: bool = True, limit_margin_deg: float | None = None,
               episodes: Sequence[int] | None = None, ray: str | None = None,
               jobs: int | None = None, calibration: str | None = None,
               outcome_source: str | None = None, measures: MeasureSettings = DEFAULT_MEASURES) -> int:
    """``inspector export``: write one recording per rollout (or dataset episode); returns the exit code.

    Args:
        path: a session, a rollout directory, a DreamZero-SO101 source directory, or a LeRobot
            dataset (with ``episodes``).
        output: a ``.rrd`` file when one rollout is exported; otherwise (or when it is an
            existing directory) a directory that receives ``<tag>.rrd`` per rollout.
        rollout: export only the rollout with this tag.
        views: camera views to include (default: all).
        dataset: LeRobot dataset with the GT episodes.
        use_cache: take video metrics from the metrics cache (and keep new ones there).
        limit_margin_deg: joint-limit margin [deg] (default: the usual 2 deg).
        episodes: the dataset episodes to export (``path`` a dataset).
        ray: write the recordings as Ray tasks at this address (see :mod:`inspector.jobs.ray`).
        jobs: worker processes writing several recordings (default: one per core); one rollout
            is written in this process.
        calibration: a GR00T-Dreams dump's calibration (``--calibration``; None: its default).
        outcome_source: the outcome source whose success and progress each recording shows
            (``--outcome-source``; None: a label over a file over sim/recording).
        measures: the sanity measures' tolerances.

    Bad input prints ``error: <file>: <what>`` to stderr and returns 2; the other rollouts of a
    session are still exported when one of them is broken.
    """
    margin = DEFAULT_LIMIT_MARGIN_DEG if limit_margin_deg is None else limit_margin_deg
    cache = MetricsCache(enabled=use_cache)
    errors = 0
    try:
        # lazy: workers read the arrays of what they write; one rollout's are read when it is
        sources = open_sources([path], dataset=dataset, datasets=True, lazy=True, calibration=calibration)
        try:
            if sources.datasets:
                return _export_episodes(sources.datasets[0], episodes, Path(output), views, margin)
            if episodes:
                raise InspectorError(path, "--episode applies to a LeRobot dataset; this is a session")
            targets = _plan_outputs(sources, Path(path), Path(output), rollout, views)
            if ray is not None:

                return 2 if export_on_ray(targets, ray, views, margin, use_cache, outcome_source, measures) else 0
            if len(targets) > 1:

                failed = export_in_processes(targets, worker_count(jobs, len(targets)), views, margin, use_cache,
                                             outcome_source, measures)
                return 2 if failed else 0
            from .recording import export_rollout  # written here: imported only now (see .files)

            for session, tag, dest in targets:
                if tag in session.errors:
                    _print_error(session.errors[tag])
                    errors += 1
                    continue
                bar = FractionBar(tag)
                try:
                    export_rollout(session.rollouts[tag], dest, views, margin, cache, progress=bar,
                                   outcome_source=outcome_source, measures=measures)
                except InspectorError as exc:
                    bar.close()
                    _print_error(exc)
                    errors += 1
                    continue
                bar.close()
                print(f"wrote {dest} ({format_size(dest.stat().st_size)})")
        finally:
            sources.close()
    except InspectorError as exc:
        _print_error(exc)
        return 2
    return 2 if errors else 0


def _export_episodes(ds, episodes: Sequence[int] | None, output: Path, views: Sequence[str] | None,
                     margin: float) -> int:
    """Recordings of dataset episodes: the commanded and measured arms, the cameras, the series."""
    if not episodes:
        raise InspectorError(ds.root, f"choose the episode(s) to export with --episode N "
                                      f"(episodes {ds.describe_episodes()})")
    missing = [i for i in episodes if i not in ds.episode_indexes()]
    if missing:
        raise InspectorError(ds.root, f"no episode {missing[0]}; episodes {ds.describe_episodes()}")
    name = dataset_name(ds).replace("/", "_")
    one_file = output.suffix == RRD_SUFFIX and not output.is_dir()
    if one_file and len(episodes) > 1:
        raise InspectorError(output, f"one file for {len(episodes)} episodes; give a directory")
    if not one_file and output.exists() and not output.is_dir():
        raise InspectorError(output, "exists and is not a directory")
    from ..analysis.timeline import build_timeline
    from .recording import write_recording  # imported only for what is written here (see .files)

    errors = 0
    for index in dict.fromkeys(episodes):
        dest = output if one_file else output / f"{name}_episode_{index}{RRD_SUFFIX}"
        bar = FractionBar(f"episode {index}")
        try:
            rollout, gt = episode_rollout(ds, index)
            write_recording(build_timeline(rollout, gt=gt, limit_margin_deg=margin), dest, views=views, progress=bar)
        except InspectorError as exc:
            _print_error(exc)
            errors += 1
            continue
        finally:
            bar.close()
        print(f"wrote {dest} ({format_size(dest.stat().st_size)})")
    return 2 if errors else 0


def _plan_outputs(sources, path: Path, output: Path, tag: str | None, views: Sequence[str] | None):
    """[(session, tag, destination)] for the rollouts asked for."""
    available = [(s, t) for s in sources.sessions for t in s.tags()]
    if tag is not None:
        chosen = [(s, t) for s, t in available if t == tag]
        if not chosen:
            raise InspectorError(path, f"no rollout {tag!r}; rollouts: {[t for _, t in available]}")
    else:
        chosen = available
    if not chosen:
        raise InspectorError(path, "no rollouts to export")
    if views:
        known = {v for s, t in chosen if t in s.rollouts
                 for v in (*s.rollouts[t].views, *s.rollouts[t].gt_views)}
        missing = [v for v in views if v not in known]
        if missing:
            raise InspectorError(path, f"no view {missing[0]!r} in any rollout; views: {sorted(known)}")
    if output.suffix == RRD_SUFFIX and not output.is_dir():
        if len(chosen) > 1:
            raise InspectorError(output, f"one file for {len(chosen)} rollouts; give a directory "
                                         "or pick one with --rollout")
        return [(chosen[0][0], chosen[0][1], output)]
    if output.exists() and not output.is_dir():
        raise InspectorError(output, "exists and is not a directory")
    return [(s, t, output / f"{t}{RRD_SUFFIX}") for s, t in chosen]


def _print_error(exc: InspectorError) -> None:
    print(f"error: {exc}", file=sys.stderr)
