"""The DreamZero-SO101 evaluation format as the importer registry sees it: ``inspector info`` on a
checkout (each rollout and listed sample as the importer would read it, nothing decoded, nothing
written, with its distribution and what the checkout lacks: a sample listed without its folder is
a rollout without video), and the entry points of :mod:`.dreamzero_so101`'s import."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ...errors import InspectorError
from ...units import Units
from .dreamzero_so101 import Checkout, find_sources, import_dreamzero, load_in_memory, unique_tag

__all__ = ["describe", "format_description", "import_command", "load_in_memory", "recognises"]

FORMAT = "dreamzero-so101"
LAYOUT_NAME = "DreamZero-SO101 evaluation"


def is_dreamzero_so101(path: Path) -> bool:
    """True when :func:`find_sources` finds anything at ``path``."""
    try:
        find_sources(path)
    except InspectorError:
        return False
    return True


recognises = is_dreamzero_so101


def import_command(src: str | Path, dest: str | Path, *, overwrite: bool = False, dataset: str | None = None,
                   episode: int | None = None) -> Path:
    """``inspector import dreamzero-so101 SRC -o DEST [--dataset --episode]``."""
    return import_dreamzero(src, dest, dataset=dataset, episode=episode, overwrite=overwrite)


def describe(src: Path, calibration: str | None = None) -> dict[str, Any]:
    """What ``inspector info`` says about the rollouts under ``src`` (no ``calibration``: the
    model's joints are the dataset's)."""
    sources = find_sources(src)
    checkout = Checkout(Path(src), sources)
    rollouts: list[dict[str, Any]] = []
    errors: dict[str, str] = {}
    used: set[str] = set()
    for source in sources:
        tag = unique_tag(source.path, Path(src), used)
        try:
            args = checkout.rollout_args(source, tag, cut_mosaic=False)
        except InspectorError as exc:
            errors[tag] = str(exc)
            continue
        extra = args["extra"]
        actions = args["actions"]
        rollouts.append({"tag": tag, "kind": args["kind"], "n_chunks": int(actions.shape[0]),
                         "horizon": int(actions.shape[1]), "views": sorted(args["videos"]),
                         "has_gt_joints": args.get("gt_actions") is not None, "prompt": args["prompt"],
                         "distribution": extra.get("distribution"), "dataset": extra.get("dataset"),
                         "warnings": list(extra.get("source_notes", []))})
    units = Units("degrees")
    return {"format": FORMAT, "layout": LAYOUT_NAME, "units": units.to_json(), "units_label": units.label(),
            "rollouts": rollouts, **({"errors": errors} if errors else {})}


def format_description(info: dict[str, Any]) -> str:
    lines = [f"{info['layout']}: {len(info['rollouts'])} rollout(s), units: {info['units_label']}"]
    width = max([12] + [len(r["tag"]) for r in info["rollouts"]])
    lines.append(f"{'tag':<{width}} {'kind':<15} {'chunks':>6} {'horizon':>7}  {'GT joints':<9}  "
                 f"{'distribution':<12}  views")
    for r in info["rollouts"]:
        lines.append(f"{r['tag']:<{width}} {r['kind']:<15} {r['n_chunks']:>6} {r['horizon']:>7}  "
                     f"{'yes' if r['has_gt_joints'] else 'no':<9}  {r['distribution'] or '-':<12}  "
                     f"{', '.join(r['views']) or 'none'}")
        lines += [f"{'':<{width}} warning: {w}" for w in r["warnings"]]
    for tag, err in info.get("errors", {}).items():
        lines.append(f"{tag:<{width}} error: {err}")
    return "\n".join(lines)
