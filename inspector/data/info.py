"""``inspector info``: what a PATH holds, in whichever layout it is; a directory no layout fits gets
one line naming the layouts it knows (:data:`.sources.RAW_LAYOUTS`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import InspectorError
from .importers import dreamzero_offline, dreamzero_served, dreamzero_so101_info, lerobot_eval
from .importers.groot_dreams import LAYOUT as GROOT_DREAMS
from .importers.groot_dreams import NeuralTrajectories, describe_layout, format_layout, is_groot_dreams
from .lerobot_dataset import INFO_PATH, LeRobotDataset, is_lerobot_dataset
from .session import CHAINED_KINDS, is_rollout, is_session, load_rollout, open_session
from .sources import no_layout_fits


def describe(path: Path, calibration: str | None = None) -> dict[str, Any]:
    """A JSON-ready description of a dataset (``format: lerobot``), a session (``session``) or a
    GR00T-Dreams dump (``groot-dreams``, mapped with ``calibration``)."""
    if path.is_dir() and is_groot_dreams(path):
        return describe_layout(NeuralTrajectories(path, calibration))
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
    if dreamzero_offline.find_runs(path):
        return dreamzero_offline.describe(path)
    if lerobot_eval.is_eval_output(path):
        return lerobot_eval.describe(path)
    if dreamzero_served.is_served(path):
        return dreamzero_served.describe(path)
    if dreamzero_so101_info.is_dreamzero_so101(path):
        return dreamzero_so101_info.describe(path)
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
    if info["format"] == GROOT_DREAMS:
        return format_layout(info)
    if info["format"] == dreamzero_offline.FORMAT:
        return dreamzero_offline.format_description(info)
    if info["format"] == dreamzero_served.FORMAT:
        return dreamzero_served.format_description(info)
    if info["format"] == lerobot_eval.FORMAT:
        return lerobot_eval.format_description(info)
    if info["format"] == dreamzero_so101_info.FORMAT:
        return dreamzero_so101_info.format_description(info)
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
