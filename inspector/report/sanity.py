"""``inspector report --sanity``: the five tests of the DreamZero-SO101 evaluation report, each
``pass``, ``partial``, ``fail`` or ``not measurable``, with the figure behind it and the threshold
that decided it.

1. action-chunk fidelity: single-chunk samples whose per-step squared error stays under the
   threshold over the first steps of the horizon;
2. latent stability: the silhouette of the episodes' latent clusters (rollouts' ``latents.npy``);
3. joint coherence: rollouts whose neighbouring joints keep the GT's coupling;
4. multi-task disambiguation: prompt pairs from one start told apart in the first chunk, and the
   chunk where they collapse;
5. autoregressive rollout: chained rollouts that complete the task in imagination.

Thresholds come from ``assets/sanity.json`` (the seed report's where it states one; docs/report.md
says what each means), overridable by a JSON file of the same shape holding only the values to
change (``--sanity-config``).
"""

from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path
from typing import Any, TypedDict

from ..errors import InspectorError

VERDICTS = ("pass", "partial", "fail", "not measurable")


class SanityTest(TypedDict):
    test: str
    verdict: str
    figure: str
    threshold: str


def default_thresholds() -> dict[str, dict[str, float]]:
    text = resources.files("inspector.report").joinpath("assets/sanity.json").read_text(encoding="utf-8")
    return json.loads(text)


def load_thresholds(path: str | Path | None = None) -> dict[str, dict[str, float]]:
    """The default thresholds, with those of ``path`` over them.

    Raises:
        InspectorError: the file cannot be read, is not a JSON object of objects, or names an
            unknown test or key, or a value that is not a number.
    """
    out = default_thresholds()
    if path is None:
        return out
    try:
        given = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise InspectorError(path, exc.strerror or str(exc)) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise InspectorError(path, f"not JSON ({exc})") from None
    if not isinstance(given, dict):
        raise InspectorError(path, f"expected an object of tests, found {type(given).__name__}")
    for test, values in given.items():
        if test not in out or not isinstance(values, dict):
            raise InspectorError(path, f"{test}: unknown test; tests: {sorted(out)}")
        for key, value in values.items():
            if key not in out[test]:
                raise InspectorError(path, f"{test}.{key}: unknown threshold; {test} has {sorted(out[test])}")
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise InspectorError(path, f"{test}.{key}: expected a number, found {value!r}")
            out[test][key] = float(value)
    return out


def _share(n: int, of: int) -> str:
    return "pass" if n == of else "partial" if n > 0 else "fail"


def action_chunk_fidelity(rows: list[dict[str, Any]], t: dict[str, float]) -> SanityTest:
    steps, limit = int(t["steps"]), t["max_step_mse_deg2"]
    threshold = f"per-step MSE < {limit:g} deg^2 over the first {steps} steps of each single chunk"
    worst = []
    for r in rows:
        mse = r.get("per_step_mse")
        if r["kind"] == "single_chunk" and mse:
            worst.append(max(mse[:steps]))
    if not worst:
        return {"test": "action-chunk fidelity", "verdict": "not measurable",
                "figure": "not measurable: no single chunk with GT joints", "threshold": threshold}
    good = sum(w < limit for w in worst)
    return {"test": "action-chunk fidelity", "verdict": _share(good, len(worst)),
            "figure": f"{good}/{len(worst)} samples within; largest early step MSE per sample "
                      f"{', '.join(f'{w:.2f}' for w in worst)} deg^2", "threshold": threshold}


def latent_stability(latents: dict[str, Any] | None, t: dict[str, float]) -> SanityTest:
    threshold = (f"episode silhouette >= {t['pass_silhouette']:g} (partial >= {t['partial_silhouette']:g})")
    if latents is None or latents.get("silhouette") is None:
        why = "no latents" if latents is None else (latents.get("note") or "no latents").removeprefix("not measurable: ")
        return {"test": "latent stability", "verdict": "not measurable", "figure": f"not measurable: {why}",
                "threshold": threshold}
    s = latents["silhouette"]
    verdict = "pass" if s >= t["pass_silhouette"] else "partial" if s >= t["partial_silhouette"] else "fail"
    return {"test": "latent stability", "verdict": verdict,
            "figure": f"silhouette {s:.3f} over {latents['n_vectors']} latents of {latents['n_episodes']} episodes",
            "threshold": threshold}


def joint_coherence(rows: list[dict[str, Any]], t: dict[str, float]) -> SanityTest:
    limit = t["max_coupling_error_deg"]
    threshold = f"shoulder-elbow and elbow-wrist coupling error <= {limit:g} deg"
    worst = [(r["tag"], max(c["coupling_error_deg"].values())) for r in rows
             if (c := r.get("joint_coherence")) and c["coupling_error_deg"]]
    if not worst:
        return {"test": "joint coherence", "verdict": "not measurable",
                "figure": "not measurable: no rollout with GT joints", "threshold": threshold}
    good = sum(w <= limit for _, w in worst)
    tag, largest = max(worst, key=lambda x: x[1])
    return {"test": "joint coherence", "verdict": _share(good, len(worst)),
            "figure": f"{good}/{len(worst)} rollouts within; largest {largest:.2f} deg ({tag})", "threshold": threshold}


def multi_task_disambiguation(pairs: list[dict[str, Any]], t: dict[str, float]) -> SanityTest:
    limit = t["min_first_chunk_distance_deg"]
    threshold = f"prompt pairs >= {limit:g} deg apart in the first chunk; collapse chunk reported"
    if not pairs:
        return {"test": "multi-task disambiguation", "verdict": "not measurable",
                "figure": "not measurable: no two prompts from one start", "threshold": threshold}
    told = [p for p in pairs if p["per_chunk"] and p["per_chunk"][0] >= limit]
    collapsed = [p for p in told if p["collapse_chunk"] is not None]
    verdict = "fail" if not told else "pass" if len(told) == len(pairs) and not collapsed else "partial"
    parts = [f"{len(told)}/{len(pairs)} pairs apart in chunk 0"]
    parts += [f"{p['a']} vs {p['b']}: chunk 0 {p['per_chunk'][0]:.2f} deg, "
              + ("never collapse" if p["collapse_chunk"] is None else f"collapse from chunk {p['collapse_chunk']}")
              for p in pairs]
    return {"test": "multi-task disambiguation", "verdict": verdict, "figure": "; ".join(parts), "threshold": threshold}


def autoregressive_rollout(rows: list[dict[str, Any]], t: dict[str, float]) -> SanityTest:
    share = t["min_completed_fraction"]
    threshold = f">= {100 * share:g}% of chained rollouts complete the task in imagination"
    chained = [r for r in rows if r.get("seams") is not None]
    measured = [r for r in chained if r.get("completion") is not None]
    breaks = [f"{r['tag']} {v}: chunk {b}" for r in chained for v, b in sorted((r.get("video_break") or {}).items())
              if b is not None]
    video = f"; video breaks: {', '.join(breaks)}" if breaks else ("; no video breaks" if chained else "")
    if not measured:
        why = "no autoregressive rollout" if not chained else "no GT joints"
        return {"test": "autoregressive rollout", "verdict": "not measurable",
                "figure": f"not measurable: {why}{video}", "threshold": threshold}
    done = [r for r in measured if r["completion"]["time_s"] is not None]
    n, of = len(done), len(measured)
    verdict = "pass" if n >= share * of and n > 0 else "partial" if n > 0 else "fail"
    return {"test": "autoregressive rollout", "verdict": verdict,
            "figure": f"{n}/{of} complete in imagination{video}", "threshold": threshold}


def sanity_tests(report: dict[str, Any], thresholds: dict[str, dict[str, float]] | None = None) -> list[SanityTest]:
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


def add_sanity(report: dict[str, Any], thresholds: dict[str, dict[str, float]] | None = None) -> None:
    """Put ``sanity`` (the five tests) and ``sanity_headline`` into ``report``."""
    tests = sanity_tests(report, thresholds)
    report["sanity"] = tests
    report["sanity_headline"] = headline(tests)
