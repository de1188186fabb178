"""``inspector info``: what a PATH holds, in whichever layout it is (a session, a LeRobot dataset,
or a format of the importer registry, :data:`.importers.FORMATS`); a path no layout fits gets one
line naming the layouts it knows (:func:`.importers.no_layout_fits`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import InspectorError
from .importers import FORMATS, GROOT_DREAMS, format_named, no_layout_fits
from .lerobot_dataset import INFO_PATH, LeRobotDataset, is_lerobot_dataset
from .session import CHAINED_KINDS, is_rollout, is_session, load_rollout, open_session


def describe(path: Path, calibration: str | None = None) -> dict[str, Any]:
    """A JSON-ready description of a dataset (``format: lerobot``), a session (``session``) or a
    GR00T-Dreams dump (``groot-dreams``, mapped with ``calibration``)."""
    trajectories = format_named(GROOT_DREAMS)  # before LeRobot's: a dump holds meta/info.json too
    if trajectories is not None and trajectories.importer.recognises(path):
        return trajectories.importer.describe(path, calibration=calibration)
    # meta/info.json present but unreadable: say what is wrong with it, not "neither ... nor"
    if is_lerobot_dataset(path) or ((path / INFO_PATH).is_file() and not is_session(path)):
        ds = LeRobotDataset(path)
        return {
            "format": "lerobot",
            "codebase_version": ds.codebase_version,
            "fps": ds.fps,
            "robot_type": ds.robot_type,
            "cameras": list(ds.cameras),
            "episodes": [{"index": e.index, "length": e.length, "task": e.task} for e in ds.episodes],
        }
    if is_session(path):
        session = open_session(path)
        rollouts = [_rollout_info(r) for r in session.rollouts.values()]
        info: dict[str, Any] = {"format": "session", "name": session.name,
                                "units": session.units.to_json(), "units_label": session.units.label(),
                                "model": session.model, "gt_source": session.gt_source,
                                "gt_dataset": str(session.dataset_root) if session.dataset_root else None,
                                "rollouts": sorted(rollouts, key=lambda r: r["tag"])}
        if session.errors:
            info["errors"] = {tag: str(err) for tag, err in sorted(session.errors.items())}
        return info
    if is_rollout(path):
        return {"format": "session", "rollouts": [_rollout_info(load_rollout(path))]}
    if not path.exists():
        raise InspectorError(path, "not found")
    for fmt in FORMATS:
        if fmt is not trajectories and fmt.importer.recognises(path):
            return fmt.importer.describe(path, calibration=calibration)
    raise no_layout_fits(path)


def _rollout_info(r: Any) -> dict[str, Any]:
    notes = r.extra.get("source_notes") if isinstance(r.extra, dict) else None  # what its importer said
    return {"tag": r.tag, "kind": r.kind, "n_chunks": r.n_chunks, "horizon": r.horizon,
            "executed_per_chunk": r.executed_per_chunk, "views": list(r.views),
            "has_gt_joints": r.has_gt_joints or _dataset_has_episode(r), "video_only": not r.has_joints,
            **({"warnings": [str(n) for n in notes]} if isinstance(notes, list) and notes else {})}


def _dataset_has_episode(r: Any) -> bool:
    root = r.session.dataset_root if r.session is not None else None
    return bool(root is not None and root.exists() and r.episode_index is not None)


def format_info(info: dict[str, Any]) -> str:
    """Readable table of :func:`describe`'s output."""
    fmt = format_named(info["format"])
    if fmt is not None:
        return fmt.importer.format_description(info)
    if info["format"] == "lerobot":
        lines = [f"LeRobot dataset {info['codebase_version']}, {info['robot_type']}, {info['fps']} fps, "
                 f"cameras: {', '.join(info['cameras']) or 'none'}",
                 f"{'episode':>7}  {'length':>6}  task"]
        lines += [f"{e['index']:>7}  {e['length']:>6}  {e['task']}" for e in info["episodes"]]
        return "\n".join(lines)
    lines = [f"session {info.get('name', '')}".rstrip()]
    model = info.get("model") or {}
    if "units_label" in info:  # a whole session (not one rollout named on its own)
        gt = info.get("gt_source") or {}
        lines += [f"model: {' / '.join(str(model[k]) for k in ('name', 'checkpoint') if model.get(k)) or '-'}",
                  f"units: {info['units_label']}",
                  f"GT source: {info.get('gt_dataset') or gt.get('repo_id') or 'carried with each rollout, or none'}"]
    width = max([16] + [len(r["tag"]) for r in info["rollouts"]])
    lines.append(f"{'tag':<{width}} {'kind':<16} {'chunks':>6} {'horizon':>7} {'exec':>4}  {'GT joints':<9}  views")
    for r in info["rollouts"]:
        # a single chunk is judged on its whole horizon: "executed" does not apply
        executed = r["executed_per_chunk"] if r["kind"] in CHAINED_KINDS else "-"
        lines.append(f"{r['tag']:<{width}} {r['kind']:<16} {r['n_chunks']:>6} {r['horizon']:>7} "
                     f"{executed:>4}  {'yes' if r['has_gt_joints'] else 'no':<9}  "
                     f"{', '.join(r['views'])}{'  (video only: no joints)' if r.get('video_only') else ''}")
        lines += [f"{'':<{width}} warning: {w}" for w in r.get("warnings", [])]
    for tag, err in info.get("errors", {}).items():
        lines.append(f"{tag:<{width}} error: {err}")
    return "\n".join(lines)
