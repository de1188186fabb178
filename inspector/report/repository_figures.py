"""What a rollout's source says of it, beside inspector's own measurements: the distribution it
comes from, its dataset, notes on how it was read, and the source repository's own figures.

These come from the importer (``extra.distribution``, ``extra.dataset``, ``extra.source_notes``,
``extra.reference_metrics``), not from the metrics cache: they are set on each row after the
cache, so an edited summary file shows at once. The repository's figures are labelled as its own
and never stand in for a measurement (a DreamZero-SO101 ``honest_summary.json`` drift sits beside
inspector's drift, not in its place).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

Row = dict[str, Any]
LABEL = "the repository's own figures, read from its files as they are; not measured by inspector"
# An index file's figures about all its samples (``aggregate.json:mean_action_rmse_deg``).
GROUP_FILES = ("aggregate.json",)


def attach_source_facts(sources: Any, rows: Mapping[tuple[str, str], Row]) -> list[str]:
    """Set ``distribution``, ``distribution_source``, ``dataset`` and ``repository_figures`` on
    each row of ``rows`` ((session root, tag) -> row) from its rollout's ``extra``. Returns the
    rollouts' source notes as warnings (``f254: no sample folder ...: shown without video``)."""
    warnings = []
    for session in sources.sessions:
        for tag, rollout in sorted(session.rollouts.items()):
            row = rows.get((str(session.root), tag))
            if row is None:
                continue
            extra = rollout.extra if isinstance(rollout.extra, dict) else {}
            for key in ("distribution", "distribution_source", "dataset"):
                row[key] = extra[key] if isinstance(extra.get(key), str) else None
            row["repository_figures"] = _figures(extra)
            notes = extra.get("source_notes")
            warnings += [f"{tag}: {n}" for n in (notes if isinstance(notes, list) else []) if isinstance(n, str)]
    return warnings


def _figures(extra: Mapping[str, Any]) -> dict[str, Any] | None:
    """``{"label", "figures", "notes", "files"}`` of the finite figures in ``reference_metrics``
    (keys ``field`` from the rollout's own meta.json, ``file:field`` from a summary file)."""
    ref = extra.get("reference_metrics")
    if not isinstance(ref, Mapping):
        return None
    figures = {k: v for k, v in ref.items() if isinstance(k, str) and _finite(v)}
    if not figures:
        return None
    notes, files = extra.get("reference_notes"), extra.get("reference_sources")
    return {"label": LABEL, "figures": figures,
            "notes": {k: v for k, v in notes.items() if isinstance(v, str)} if isinstance(notes, Mapping) else {},
            "files": {k: v for k, v in files.items() if isinstance(v, str)} if isinstance(files, Mapping) else {}}


def _finite(value: Any) -> bool:
    """A finite number or bool, or a list of finite numbers: what strict JSON can carry."""
    values = value if isinstance(value, list) else [value]
    try:
        return all(isinstance(v, (int, float)) and math.isfinite(float(v)) for v in values)
    except OverflowError:
        return False


def repository_lines(rows: list[Row]) -> list[str]:
    """The report's text section: the distribution of each rollout, then the repository's
    figures (per chained rollout; once per index file, with inspector's mean over its samples)."""
    lines: list[str] = []
    by_distribution: dict[str, list[str]] = {}
    for r in rows:
        by_distribution.setdefault(r.get("distribution") or "not stated", []).append(r["tag"])
    if set(by_distribution) != {"not stated"}:
        lines.append("Distribution (what the source says: an aggregate's zero_shot_disclosure, its dataset, its folders)")
        lines += [f"  {d}: {', '.join(tags)}" for d, tags in sorted(by_distribution.items())]
        lines.append("")
    figured = [r for r in rows if r.get("repository_figures")]
    width = max([0] + [len(r["tag"]) for r in figured])
    # a sample's own figures stay in the JSON; its list's figures come once, below
    body = [f"  {r['tag']:<{width}}  {_by_file(r['repository_figures']['figures'])}"
            for r in figured if r["kind"] != "single_chunk"]
    for (name, where), group in _groups(figured).items():
        own = [r["rmse_deg"] for r in group if r.get("rmse_deg") is not None]
        ours = f"{sum(own) / len(own):.2f} deg" if len(own) == len(group) else (
            f"{sum(own) / len(own):.2f} deg over the {len(own)} with GT joints" if own else "not measured (no GT joints)")
        theirs = {k.partition(":")[2]: v for k, v in group[0]["repository_figures"]["figures"].items()
                  if k.startswith(name + ":")}
        body.append(f"  {where}: {_fields(theirs)}; inspector's mean RMSE of the same {len(group)} sample(s): {ours}")
    return lines + ([f"Source figures ({LABEL})", *body, ""] if body else [])


def _groups(rows: list[Row]) -> dict[tuple[str, str], list[Row]]:
    """The rows that carry each index file's figures, by (file name, path)."""
    out: dict[tuple[str, str], list[Row]] = {}
    for r in rows:
        files = r["repository_figures"]["files"]
        for name in GROUP_FILES:
            if name in files:
                out.setdefault((name, files[name]), []).append(r)
    return out


def _by_file(figures: Mapping[str, Any]) -> str:
    """``meta.json: mean_drift_deg 137.64, ...; honest_summary.json: time_aligned_mean 96.82, ...``
    (keys ``field`` are the rollout's meta.json's, ``file:field`` a summary file's)."""
    files: dict[str, dict[str, Any]] = {}
    for key, value in figures.items():
        name, _, field = key.rpartition(":")
        files.setdefault(name or "meta.json", {})[field] = value
    return "; ".join(f"{name}: {_fields(fields)}" for name, fields in files.items())


def _fields(figures: Mapping[str, Any]) -> str:
    """``n_samples 8, mean_action_rmse_deg 11.91, ...`` (lists, per joint or per step, left to the JSON)."""
    parts = []
    for field, value in figures.items():
        if isinstance(value, list):
            continue
        parts.append(f"{field} {str(value).lower() if isinstance(value, bool) else f'{value:.2f}' if isinstance(value, float) else value}")
    return ", ".join(parts)
