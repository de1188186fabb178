"""``inspector report --sanity``: the five tests of the DreamZero-SO101 evaluation report, each
``pass``, ``partial``, ``fail`` or ``not measurable``, with the figure behind it, the threshold
that decided it and the rows it used (docs/report.md says, per test, what the seed report defines,
what is computed here, on which rows, and why the two may differ).

1. action-chunk fidelity: single-chunk samples of the training distribution (zero-shot samples
   get their own line, never the verdict): the mean per-step MSE curve over the first steps
   (rule ``mean_curve``, the seed's) or every sample's own largest early step (``per_sample``);
2. latent stability: the silhouette of the episodes' latent clusters (rollouts' ``latents.npy``);
3. joint coherence: rollouts that span their episode with GT joints keep the GT's coupling, and
   each coupled pair keeps the GT's relative phase;
4. multi-task disambiguation: prompt pairs from one start told apart in the first chunk, and the
   chunk where they collapse;
5. autoregressive rollout: chained rollouts that complete the task in imagination, and where
   their imagined video breaks relative to the real episode's end.

Thresholds come from ``assets/sanity.json``, overridable by a JSON file of the same shape holding
only the values to change (``--sanity-config``); every value is range-checked where it is read.
"""

from __future__ import annotations

import math
import os
import stat
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from ..analysis.coherence import COUPLED_PAIRS
from ..data.session import parse_json, read_json_object
from ..errors import InspectorError

VERDICTS = ("pass", "partial", "fail", "not measurable")
FIDELITY_RULES = ("mean_curve", "per_sample")
ZERO_SHOT = "zero-shot"
TRAINING = "training"

Thresholds = dict[str, dict[str, Any]]


class SanityTest(TypedDict):
    test: str
    verdict: str
    figure: str
    threshold: str
    rows: dict[str, int]  # how many rows the verdict used, and how many were set aside and why


@dataclass(frozen=True)
class _Range:
    """The values a threshold may take: a number from ``lo`` to ``hi`` (``lo`` itself excluded
    when ``above``), an integer when ``integer``."""

    lo: float
    hi: float
    above: bool = False
    integer: bool = False

    def holds(self, value: float) -> bool:
        return (value > self.lo if self.above else value >= self.lo) and value <= self.hi \
            and (not self.integer or float(value).is_integer())

    def __str__(self) -> str:
        kind = "an integer" if self.integer else "a number"
        return f"{kind} {'>' if self.above else '>='} {self.lo:g} and <= {self.hi:g}"


# every threshold's allowed values (a config of "steps": 0 would leave nothing to compare)
RANGES: dict[str, dict[str, _Range | tuple[str, ...]]] = {
    "action_chunk_fidelity": {"max_step_mse_deg2": _Range(0, 1e6, above=True), "steps": _Range(1, 10_000, integer=True),
                              "rule": FIDELITY_RULES},
    "latent_stability": {"pass_silhouette": _Range(-1, 1), "partial_silhouette": _Range(-1, 1)},
    "joint_coherence": {"max_coupling_error_deg": _Range(0, 360), "max_pair_lag_s": _Range(0, 60),
                        "min_episode_share": _Range(0, 1, above=True)},
    "multi_task_disambiguation": {"min_first_chunk_distance_deg": _Range(0, 360)},
    "autoregressive_rollout": {"min_completed_fraction": _Range(0, 1, above=True)},
}


def default_thresholds() -> Thresholds:
    """The shipped thresholds (``assets/sanity.json``), checked as a user's file is."""
    asset = resources.files("inspector.report").joinpath("assets/sanity.json")
    where = Path(str(asset))
    out: Thresholds = {test: {} for test in RANGES}
    _apply(out, parse_json(where, asset.read_bytes()), where)
    missing = [f"{test}.{key}" for test, keys in RANGES.items() for key in keys if key not in out[test]]
    if missing:
        raise InspectorError(where, f"{missing[0]}: missing (every threshold needs a default)")
    return out


def load_thresholds(path: str | Path | None = None) -> Thresholds:
    """The default thresholds, with those of ``path`` over them.

    Raises:
        InspectorError: the file is not a regular file, cannot be read, is too large, nested past
            the parser's depth or not a JSON object of objects; or it names an unknown test or key,
            or a value of the wrong type or out of its range (the message gives the range).
    """
    out = default_thresholds()
    if path is None:
        return out
    where = Path(path)
    _require_regular_file(where)  # a device or a FIFO would be read forever, or block
    _apply(out, read_json_object(where), where)
    return out


def _require_regular_file(path: Path) -> None:
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return  # missing or unreadable: the JSON reader names it
    kinds = ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
             (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"))
    kind = next((name for test, name in kinds if test(mode)), None if stat.S_ISREG(mode) else "not a plain file")
    if kind is not None:
        raise InspectorError(path, f"is {kind}, not a regular file: a sanity config is a JSON file")


def _apply(out: Thresholds, given: dict[str, Any], path: Path) -> None:
    """Put the thresholds of ``given`` (a parsed config) into ``out``, each checked against
    :data:`RANGES`."""
    for test, values in given.items():
        if test not in RANGES:
            raise InspectorError(path, f"{test}: unknown test; tests: {sorted(RANGES)}")
        if not isinstance(values, dict):
            raise InspectorError(path, f"{test}: expected an object of thresholds, found {type(values).__name__}")
        for key, value in values.items():
            allowed = RANGES[test].get(key)
            if allowed is None:
                raise InspectorError(path, f"{test}.{key}: unknown threshold; {test} has {sorted(RANGES[test])}")
            if isinstance(allowed, tuple):
                if not isinstance(value, str) or value not in allowed:
                    raise InspectorError(path, f"{test}.{key}: expected one of {', '.join(map(repr, allowed))}, found {value!r}")
                out[test][key] = value
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InspectorError(path, f"{test}.{key}: expected a number, found {value!r}")
            if not allowed.holds(value):
                shown = repr(value) if len(repr(value)) <= 24 else f"{repr(value)[:12]}..."  # an integer of 4,000 digits
                raise InspectorError(path, f"{test}.{key}: {shown} is out of range: must be {allowed}")
            out[test][key] = int(value) if allowed.integer else float(value)
    latent = out["latent_stability"]
    if {"pass_silhouette", "partial_silhouette"} <= set(latent) and latent["partial_silhouette"] > latent["pass_silhouette"]:
        raise InspectorError(path, f"latent_stability.partial_silhouette: {latent['partial_silhouette']:g} is above "
                                   f"pass_silhouette {latent['pass_silhouette']:g} (partial is the lower bar)")


def _share(n: int, of: int) -> str:
    return "pass" if n == of else "partial" if n > 0 else "fail"


def _n(count: int, noun: str) -> str:
    """``1 sample``, ``2 samples``."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


def _listed(values: list[str], most: int = 10) -> str:
    return ", ".join(values[:most]) + (f", ... ({len(values) - most} more)" if len(values) > most else "")


def _early_mse(mse: Any, steps: int) -> np.ndarray | None:
    """A sample's per-step MSE over its first ``steps`` steps; None when it has fewer measured."""
    early = [v for v in (mse or [])[:steps] if isinstance(v, (int, float)) and math.isfinite(v)]
    return np.asarray(early, np.float64) if len(early) == steps else None


def _curve_max(samples: list[np.ndarray]) -> tuple[float, int]:
    """The mean per-step curve's largest value and its step (from 1)."""
    curve = np.mean(samples, axis=0)
    return float(curve.max()), int(np.argmax(curve)) + 1


def action_chunk_fidelity(rows: list[dict[str, Any]], t: dict[str, Any]) -> SanityTest:
    """Test 1 on the single chunks of the training distribution (``distribution`` "training" or
    not stated); zero-shot ones are a line of their own, rows without per-step MSE or shorter than
    ``steps`` are set aside and counted."""
    steps, limit, rule = int(t["steps"]), float(t["max_step_mse_deg2"]), str(t["rule"])
    if rule == "mean_curve":
        threshold = (f"rule mean_curve (the seed report's): the mean per-step MSE curve of the training-distribution "
                     f"single chunks (each step: mean over joints, then over samples), its largest value over steps "
                     f"1-{steps}, < {limit:g} deg^2")
    else:
        threshold = (f"rule per_sample: each training-distribution single chunk's largest per-step MSE (mean over "
                     f"joints) over steps 1-{steps} < {limit:g} deg^2 (partial: some are)")
    counts = {"in_verdict": 0, "training": 0, "unstated": 0, "zero_shot": 0, "other_distribution": 0,
              "no_per_step_mse": 0, "shorter_than_steps": 0}
    used: list[tuple[str, np.ndarray]] = []
    zero: list[np.ndarray] = []
    for r in rows:
        if r["kind"] != "single_chunk":
            continue
        early = _early_mse(r.get("per_step_mse"), steps)
        if early is None:
            counts["no_per_step_mse" if not r.get("per_step_mse") else "shorter_than_steps"] += 1
            continue
        distribution = r.get("distribution")
        if distribution == ZERO_SHOT:
            counts["zero_shot"] += 1
            zero.append(early)
        elif distribution in (None, TRAINING):
            counts["training" if distribution == TRAINING else "unstated"] += 1
            used.append((r["tag"], early))
        else:
            counts["other_distribution"] += 1
    counts["in_verdict"] = len(used)
    aside = [f"{n} {what}" for n, what in ((counts["no_per_step_mse"], "without per-step MSE (no GT joints)"),
                                           (counts["shorter_than_steps"], f"shorter than {steps} steps"),
                                           (counts["other_distribution"], "of another stated distribution")) if n]
    tail = []
    if zero:
        m, _ = _curve_max(zero)
        within = sum(float(z.max()) < limit for z in zero)
        tail.append(f"zero-shot (not in the verdict): {_n(len(zero), 'sample')}, mean curve's largest early step {m:.2f} deg^2, "
                    f"{within}/{len(zero)} samples within")
    if aside:
        tail.append("set aside: " + ", ".join(aside))
    tail_text = "".join(f"; {part}" for part in tail)
    if not used:
        return {"test": "action-chunk fidelity", "verdict": "not measurable",
                "figure": f"not measurable: no single chunk of the training distribution with per-step MSE{tail_text}",
                "threshold": threshold, "rows": counts}
    unstated = f" ({counts['unstated']} with no stated distribution)" if counts["unstated"] else ""
    worst = [float(e.max()) for _, e in used]
    per_sample = _listed([f"{w:.2f}" for w in worst])
    good = sum(w < limit for w in worst)
    if rule == "mean_curve":
        m, at = _curve_max([e for _, e in used])
        verdict = "pass" if m < limit else "fail"
        figure = (f"mean curve's largest early step {m:.2f} deg^2 (step {at}) over {_n(len(used), 'sample')}{unstated}; "
                  f"per sample {per_sample} deg^2")
    else:
        verdict = _share(good, len(used))
        figure = f"{good}/{len(used)} samples within{unstated}; largest early step MSE per sample {per_sample} deg^2"
    return {"test": "action-chunk fidelity", "verdict": verdict, "figure": figure + tail_text, "threshold": threshold,
            "rows": counts}


def latent_stability(latents: dict[str, Any] | None, t: dict[str, Any]) -> SanityTest:
    threshold = (f"episode silhouette >= {t['pass_silhouette']:g} (partial >= {t['partial_silhouette']:g})")
    n = int(latents.get("n_vectors") or 0) if latents else 0
    if latents is None or latents.get("silhouette") is None:
        why = "no latents" if latents is None else (latents.get("note") or "no latents").removeprefix("not measurable: ")
        return {"test": "latent stability", "verdict": "not measurable", "figure": f"not measurable: {why}",
                "threshold": threshold, "rows": {"latent_vectors": n}}
    s = latents["silhouette"]
    verdict = "pass" if s >= t["pass_silhouette"] else "partial" if s >= t["partial_silhouette"] else "fail"
    return {"test": "latent stability", "verdict": verdict,
            "figure": f"silhouette {s:.3f} over {latents['n_vectors']} latents of {latents['n_episodes']} episodes",
            "threshold": threshold, "rows": {"latent_vectors": n}}


def episode_share(row: dict[str, Any]) -> float | None:
    """The share of its GT episode a rollout's predicted, executed steps cover (from its start
    frame to the episode's end at most); None when the episode's length is not known."""
    length = row.get("episode_length")
    if not length or length <= 0:
        return None
    start = int(row.get("start_frame") or 0)
    executed = int(row["n_chunks"]) * int(row["steps_per_chunk"])
    return max(0, min(start + executed, length) - start) / length


def _pair_lags(c: dict[str, Any]) -> dict[str, float | None]:
    """Per coupled pair a-b, the prediction's relative lag of a against b less the GT's [s]
    (``offset_a - offset_b``: each offset is against the GT joint); None when either offset is
    not determined."""
    offsets = c.get("phase_offset_s") or {}
    out: dict[str, float | None] = {}
    for a, b in COUPLED_PAIRS:
        oa, ob = offsets.get(a), offsets.get(b)
        out[f"{a}-{b}"] = None if oa is None or ob is None else round(oa - ob, 4)
    return out


def joint_coherence(rows: list[dict[str, Any]], t: dict[str, Any]) -> SanityTest:
    """Test 3 on the rollouts whose predicted steps cover at least ``min_episode_share`` of their
    GT episode, with GT joints: coupling within the limit and no coupled pair whose relative phase
    lag differs from the GT's by more than ``max_pair_lag_s`` (a lag at the window's edge is not
    determined and decides nothing)."""
    limit, lag_limit, share = float(t["max_coupling_error_deg"]), float(t["max_pair_lag_s"]), float(t["min_episode_share"])
    threshold = (f"rollouts with GT joints over >= {100 * share:g}% of their episode: shoulder-elbow and elbow-wrist "
                 f"coupling error <= {limit:g} deg, and each pair's relative phase lag within {lag_limit:g} s of the GT's")
    counts = {"in_verdict": 0, "short_with_gt": 0, "spanning_without_gt": 0, "episode_length_unknown": 0}
    spanning, short = [], []
    for r in rows:
        cover, c = episode_share(r), r.get("joint_coherence")
        if c is None or not c.get("coupling_error_deg"):
            counts["spanning_without_gt"] += cover is not None and cover >= share
        elif cover is None:
            counts["episode_length_unknown"] += 1
        elif cover < share:
            counts["short_with_gt"] += 1
            short.append(cover)
        else:
            spanning.append(r)
    counts["in_verdict"] = len(spanning)
    aside = [f"{n} {what}" for n, what in (
        (counts["short_with_gt"], f"with GT joints over at most {100 * max(short, default=0):.0f}% of their episode"),
        (counts["spanning_without_gt"], "spanning their episode without GT joints"),
        (counts["episode_length_unknown"], "with GT joints but no known episode length")) if n]
    aside_text = f" ({', '.join(aside)})" if aside else ""
    if not spanning:
        return {"test": "joint coherence", "verdict": "not measurable",
                "figure": f"not measurable: needs GT joints over a whole episode (>= {100 * share:g}% of it): pass --dataset for "
                          f"rollouts that run their episode{aside_text}",
                "threshold": threshold, "rows": counts}
    good, off, undetermined, largest = 0, [], 0, (-1.0, "")
    for r in spanning:
        c = r["joint_coherence"]
        worst = max(c["coupling_error_deg"].values())
        largest = max(largest, (worst, r["tag"]))
        lags = _pair_lags(c)
        undetermined += sum(v is None for v in lags.values())
        bad = [f"{r['tag']} {pair} {v:+.2f} s" for pair, v in lags.items() if v is not None and abs(v) > lag_limit + 1e-9]
        off += bad
        good += worst <= limit and not bad
    parts = [f"{good}/{len(spanning)} rollouts spanning their episode within", f"largest coupling {largest[0]:.2f} deg ({largest[1]})",
             "pair lags off the GT's: " + (_listed(off) if off else "none")]
    if undetermined:
        parts.append(f"{_n(undetermined, 'pair lag')} not determined (a joint still, or its lag at the search window's edge)")
    if aside:
        parts.append("set aside: " + ", ".join(aside))
    return {"test": "joint coherence", "verdict": _share(good, len(spanning)), "figure": "; ".join(parts),
            "threshold": threshold, "rows": counts}


def multi_task_disambiguation(pairs: list[dict[str, Any]], t: dict[str, Any]) -> SanityTest:
    limit = t["min_first_chunk_distance_deg"]
    threshold = f"prompt pairs >= {limit:g} deg apart in the first chunk; collapse chunk reported"
    if not pairs:
        return {"test": "multi-task disambiguation", "verdict": "not measurable",
                "figure": "not measurable: no two prompts from one start", "threshold": threshold, "rows": {"pairs": 0}}
    told = [p for p in pairs if p["per_chunk"] and p["per_chunk"][0] >= limit]
    collapsed = [p for p in told if p["collapse_chunk"] is not None]
    verdict = "fail" if not told else "pass" if len(told) == len(pairs) and not collapsed else "partial"
    parts = [f"{len(told)}/{len(pairs)} pairs apart in chunk 0"]
    parts += [f"{p['a']} vs {p['b']}: chunk 0 {p['per_chunk'][0]:.2f} deg, "
              + ("never collapse" if p["collapse_chunk"] is None else f"collapse from chunk {p['collapse_chunk']}")
              for p in pairs]
    return {"test": "multi-task disambiguation", "verdict": verdict, "figure": "; ".join(parts), "threshold": threshold,
            "rows": {"pairs": len(pairs)}}


def video_breaks(rows: list[dict[str, Any]]) -> dict[str, list[str]]:
    """Each chained rollout's views by where their imagined video breaks against the real episode's
    end: ``holds`` (no break), ``after_end`` (at or after the first chunk that starts past the
    episode's last step: the seed report's "degrades after the real episode end"), ``before_end``
    and ``end_unknown`` (no GT episode length)."""
    out: dict[str, list[str]] = {"holds": [], "after_end": [], "before_end": [], "end_unknown": []}
    for r in rows:
        post = r.get("post_episode_chunks")
        first_after = None if post is None else int(r["n_chunks"]) - int(post)
        for view, b in sorted((r.get("video_break") or {}).items()):
            if b is None:
                out["holds"].append(f"{r['tag']} {view}")
            elif first_after is None:
                out["end_unknown"].append(f"{r['tag']} {view} at chunk {b}")
            elif b >= first_after:
                out["after_end"].append(f"{r['tag']} {view} at chunk {b} (episode over from chunk {first_after})")
            else:
                where = f"episode over from chunk {first_after}" if post else "the episode outlasts the rollout"
                out["before_end"].append(f"{r['tag']} {view} at chunk {b} ({where})")
    return out


def autoregressive_rollout(rows: list[dict[str, Any]], t: dict[str, Any]) -> SanityTest:
    """Test 5 in two halves: completion (chained rollouts with GT joints) and where each view's
    imagined video breaks against the episode's end (every chained rollout). ``pass``: the share
    completing reaches the threshold and every view holds; ``fail``: none completes; ``partial``:
    some complete, or they complete but a view breaks (after the episode's end: the seed report's
    partial; before it: said so); ``not measurable`` without completion, the video half still given."""
    share = t["min_completed_fraction"]
    threshold = (f"completion: >= {100 * share:g}% of chained rollouts with GT joints complete the task in imagination; "
                 f"video: every view holds (pass), or breaks after the episode's end (partial)")
    chained = [r for r in rows if r.get("seams") is not None]
    measured = [r for r in chained if r.get("completion") is not None]
    done = [r for r in measured if r["completion"]["time_s"] is not None]
    views = video_breaks(chained)
    counts = {"chained": len(chained), "completion_measured": len(measured), "completed": len(done),
              **{f"views_{k}": len(v) for k, v in views.items()}}
    video_parts = [f"{_n(len(views['holds']), 'view')} {'holds' if len(views['holds']) == 1 else 'hold'}"] if chained else []
    video_parts += [f"{label}: {_listed(views[key])}" for key, label in (
        ("before_end", "breaks before the episode's end"), ("after_end", "breaks after the episode's end"),
        ("end_unknown", "breaks, episode end unknown")) if views[key]]
    video = f"; video: {'; '.join(video_parts)}" if video_parts else ""
    if not measured:
        why = "no autoregressive rollout" if not chained else "no GT joints (pass --dataset)"
        return {"test": "autoregressive rollout", "verdict": "not measurable",
                "figure": f"completion not measurable: {why}{video}", "threshold": threshold, "rows": counts}
    n, of = len(done), len(measured)
    broken = sum(len(views[k]) for k in ("before_end", "after_end", "end_unknown"))
    verdict = "fail" if n == 0 else "pass" if n >= share * of and not broken else "partial"
    return {"test": "autoregressive rollout", "verdict": verdict,
            "figure": f"completion: {n}/{of} complete in imagination{video}", "threshold": threshold, "rows": counts}


def sanity_tests(report: dict[str, Any], thresholds: Thresholds | None = None) -> list[SanityTest]:
    """The five tests over a report's rows (see the module docstring)."""
    t = thresholds if thresholds is not None else default_thresholds()
    rows = report["rollouts"]
    return [action_chunk_fidelity(rows, t["action_chunk_fidelity"]),
            latent_stability(report.get("latents"), t["latent_stability"]),
            joint_coherence(rows, t["joint_coherence"]),
            multi_task_disambiguation(report.get("prompt_divergence", []), t["multi_task_disambiguation"]),
            autoregressive_rollout(rows, t["autoregressive_rollout"])]


def headline(tests: list[SanityTest]) -> str:
    """``sanity 3/5`` (tests passed of five), with the partial and unmeasured ones named."""
    passed = sum(t["verdict"] == "pass" for t in tests)
    extra = [f"{sum(t['verdict'] == v for t in tests)} {v}" for v in VERDICTS[1:]
             if any(t["verdict"] == v for t in tests)]
    return f"sanity {passed}/{len(tests)}" + (f" ({', '.join(extra)})" if extra else "")


def format_sanity(tests: list[SanityTest]) -> list[str]:
    """The verdict table as text lines."""
    width = max(len(t["test"]) for t in tests)
    lines = [f"Sanity tests: {headline(tests)}"]
    for t in tests:
        lines.append(f"  {t['test']:<{width}}  {t['verdict']:<14}  {t['figure']}")
        lines.append(f"  {'':<{width}}  {'':<14}  threshold: {t['threshold']}")
    return lines


def add_sanity(report: dict[str, Any], thresholds: Thresholds | None = None) -> None:
    """Put ``sanity`` (the five tests) and ``sanity_headline`` into ``report``."""
    tests = sanity_tests(report, thresholds)
    report["sanity"] = tests
    report["sanity_headline"] = headline(tests)
