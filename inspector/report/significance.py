"""Is the difference between A and B real? One pre-declared test per compared metric, and the
verdict, the interval and the p-value all come from it (``compare``'s ``tests``).

- Continuous metrics (RMSE, time-aligned drift, PSNR per view, progress, video-action |lag| per
  view), over the pairs with a value on both sides: Wilcoxon's signed-rank test of the
  differences B - A of the pairs that differ (ties at 0 left out), the Hodges-Lehmann shift and
  the interval that inverts the same test (:func:`inspector.stats.signed_rank_test`): the
  interval leaves 0 out exactly when the test rejects.
- Success, over the pairs with a success flag on both sides: McNemar's exact test on the
  discordant pairs and its exact conditional interval of B's rate less A's
  (:func:`inspector.stats.mcnemar_interval`). With no such pair, over each side's rollouts with a
  flag: Fisher's exact test (twice the smaller tail) and the exact conditional interval of the
  odds ratio that inverts it. When it is not significant, ``rollouts_needed`` says how many
  rollouts per side would make the observed rates' difference significant with 80% power.

The verdict is "A better" or "B better" only when the test gives p < 0.05, in the direction of its
estimate; else "no difference shown"; and "too few pairs to tell (n = 4; needs >= 6)" where no
outcome of that many informative pairs could reach 0.05 (the interval is then unbounded: null).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ..stats import (
    ALPHA,
    NO_DIFFERENCE,
    SignedRankResult,
    fisher_can_reject,
    fisher_central,
    fisher_min_per_side,
    fisher_odds_ratio,
    mcnemar_exact,
    mcnemar_interval,
    min_pairs_to_reject,
    rollouts_needed,
    signed_rank_test,
    too_few,
    verdict_from_test,
)

CONFIDENCE = 1.0 - ALPHA
Row = dict[str, Any]
Getter = Callable[[Row], "float | None"]


def _success(r: Row) -> bool | None:
    o = r.get("task_outcome")
    return None if not o else o.get("success")


def _progress(r: Row) -> float | None:
    o = r.get("task_outcome")
    return None if not o else o.get("progress")


def _drift(r: Row) -> float | None:
    d = r.get("time_aligned_drift")
    return d["mean"] if d else None


def _psnr(view: str) -> Getter:
    return lambda r: (r.get("video_psnr_db") or {}).get(view)


def _abs_lag(view: str) -> Getter:
    def get(r: Row) -> float | None:
        lag = ((r.get("video_action") or {}).get(view) or {}).get("lag_s_median")
        return None if lag is None else abs(lag)
    return get


def continuous_metrics(rows: list[Row]) -> list[tuple[str, Getter, bool]]:
    """(name, value of a row, higher is better) of every metric compared, the views' from ``rows``."""
    views = sorted({v for r in rows for v in (r.get("video_psnr_db") or {})})
    lag_views = sorted({v for r in rows for v in (r.get("video_action") or {})})
    return [("rmse_deg", lambda r: r.get("rmse_deg"), False),
            ("time_aligned_drift_deg", _drift, False),
            *((f"video_psnr_db.{v}", _psnr(v), True) for v in views),
            ("progress_pct", _progress, True),
            *((f"video_action_abs_lag_s.{v}", _abs_lag(v), False) for v in lag_views)]


def _verdict(r: SignedRankResult, higher_is_better: bool) -> str:
    if r.n_informative == 0:
        return NO_DIFFERENCE  # every pair ties
    if r.n_informative < r.min_informative or r.pvalue is None or r.estimate is None:
        return too_few(r.n_informative, r.min_informative)
    return verdict_from_test(r.pvalue, r.estimate, higher_is_better)


def continuous_test(metric: str, pairs: list[tuple[Row, Row]], get: Getter, higher_is_better: bool) -> Row | None:
    """The signed-rank test of B - A over the pairs with a value on both sides; None without one."""
    values = [(a, b) for a, b in ((get(pa), get(pb)) for pa, pb in pairs)
              if a is not None and b is not None and math.isfinite(a) and math.isfinite(b)]
    if not values:
        return None
    d = np.array([b - a for a, b in values], dtype=np.float64)
    r = signed_rank_test(d, confidence=CONFIDENCE)
    return {"metric": metric, "higher_is_better": higher_is_better, "n_pairs": r.n_pairs,
            "n_informative": r.n_informative, "ties": r.n_pairs - r.n_informative,
            "min_informative": r.min_informative, "mean_diff": float(d.mean()),
            "estimate": r.estimate, "estimate_kind": "hodges_lehmann",
            "ci95": None if r.ci is None else list(r.ci), "ci95_open": list(r.ci_open),
            "p": r.pvalue, "test": "wilcoxon_signed_rank" + (f"_{r.method}" if r.method else ""),
            "verdict": _verdict(r, higher_is_better)}


def success_test(pairs: list[tuple[Row, Row]], rows_a: list[Row], rows_b: list[Row]) -> Row | None:
    """Paired (McNemar exact) over the pairs with a success flag on both sides, else unpaired
    (Fisher exact) over each side's rows with one; None when a side has none."""
    both = [(sa, sb) for sa, sb in ((_success(a), _success(b)) for a, b in pairs) if sa is not None and sb is not None]
    record = _paired_success(both) if both else _unpaired_success(rows_a, rows_b)
    if record is not None and record["verdict"] not in ("A better", "B better"):
        record["rollouts_needed"] = rollouts_needed(record["rate_a"], record["rate_b"])
    return record


def _paired_success(both: list[tuple[bool, bool]]) -> Row:
    n = len(both)
    a_only = sum(sa and not sb for sa, sb in both)
    b_only = sum(sb and not sa for sa, sb in both)
    discordant = a_only + b_only
    rate_a, rate_b = sum(sa for sa, _ in both) / n, sum(sb for _, sb in both) / n
    need = min_pairs_to_reject(ALPHA)
    p = mcnemar_exact(a_only, b_only).pvalue
    ci = mcnemar_interval(a_only, b_only, n, CONFIDENCE) if discordant >= need else None
    verdict: str
    if discordant == 0:
        verdict = NO_DIFFERENCE
    elif discordant < need:
        verdict = too_few(discordant, need, "discordant pairs")
    else:
        verdict = verdict_from_test(p, rate_b - rate_a, True)
    return {"metric": "success", "higher_is_better": True, "paired": True, "n_pairs": n,
            "n_informative": discordant, "min_informative": need,
            "pairs": {"both": sum(sa and sb for sa, sb in both), "only_a": a_only, "only_b": b_only,
                      "neither": sum(not sa and not sb for sa, sb in both)},
            "n_a": n, "n_b": n, "rate_a": rate_a, "rate_b": rate_b, "mean_diff": rate_b - rate_a,
            "estimate": rate_b - rate_a, "estimate_kind": "rate_difference",
            "ci95": None if ci is None else list(ci), "p": p, "test": "mcnemar_exact", "verdict": verdict}


def _unpaired_success(rows_a: list[Row], rows_b: list[Row]) -> Row | None:
    flags_a = [s for s in map(_success, rows_a) if s is not None]
    flags_b = [s for s in map(_success, rows_b) if s is not None]
    if not flags_a or not flags_b:
        return None
    sa, na, sb, nb = sum(flags_a), len(flags_a), sum(flags_b), len(flags_b)
    rate_a, rate_b = sa / na, sb / nb
    p = fisher_central(sa, na, sb, nb).pvalue
    estimate, lo, hi = fisher_odds_ratio(sa, na, sb, nb, CONFIDENCE)
    if not fisher_can_reject(na, nb):
        verdict = f"too few rollouts to tell (n = {na} vs {nb}; needs >= {fisher_min_per_side(ALPHA)} a side)"
    else:
        verdict = verdict_from_test(p, rate_b - rate_a, True)
    return {"metric": "success", "higher_is_better": True, "paired": False, "n_pairs": 0,
            "n_a": na, "n_b": nb, "rate_a": rate_a, "rate_b": rate_b, "mean_diff": rate_b - rate_a,
            "estimate": estimate, "estimate_kind": "odds_ratio",
            "ci95": [lo, hi], "p": p, "test": "fisher_exact_central", "verdict": verdict}


def metric_tests(pairs: list[tuple[Row, Row]], rows_a: list[Row], rows_b: list[Row]) -> list[Row]:
    """``tests``: ``[{metric, n_pairs, mean_diff, ci95, p, test, verdict, ...}]`` for every metric
    with values on both sides (differences B - A)."""
    tests = [t for name, get, higher in continuous_metrics([*rows_a, *rows_b])
             if (t := continuous_test(name, pairs, get, higher)) is not None]
    success = success_test(pairs, rows_a, rows_b)
    return [*tests, *([success] if success is not None else [])]


def _pct(v: float) -> str:
    return f"{100 * v:+.0f}%"


def _odds(v: float | None) -> str:
    return "unbounded" if v is None else format(v, ".3g")


def _odds_estimate(t: Row) -> str:
    if t["estimate"] is None and t["rate_a"] == t["rate_b"]:
        return "undefined (every rollout alike)"  # all successes, or none, on both sides
    return _odds(t["estimate"])


def _p(t: Row) -> str:
    return "-" if t["p"] is None else format(t["p"], ".3g")


def _continuous_interval(t: Row) -> str:
    if t["ci95"] is None:
        return "interval unbounded"
    (lo, hi), (open_lo, open_hi) = t["ci95"], t.get("ci95_open") or (False, False)
    return f"{'(' if open_lo else '['}{lo:+.3g}, {hi:+.3g}{')' if open_hi else ']'}"


_TEST_NAMES = {"wilcoxon_signed_rank_exact": "Wilcoxon signed-rank, exact",
               "wilcoxon_signed_rank_permutation": "Wilcoxon signed-rank, exact permutation (ties)",
               "wilcoxon_signed_rank_normal": "Wilcoxon signed-rank, normal approximation",
               "wilcoxon_signed_rank": "Wilcoxon signed-rank", "mcnemar_exact": "McNemar exact",
               "fisher_exact_central": "Fisher exact"}


def verdict_text(t: Row) -> str:
    """One metric's verdict in a line: the verdict, the estimate with its interval and the test
    they come from."""
    return ": ".join(verdict_parts(t))


def verdict_parts(t: Row) -> tuple[str, str, str]:
    """``(metric, verdict, what it rests on)`` of :func:`verdict_text` (the app sets the verdict
    in bold)."""
    test = f"{_TEST_NAMES.get(t['test'], t['test'])} p {_p(t)}"
    if t["metric"] != "success":
        if not t["n_informative"]:
            return t["metric"], t["verdict"], f"all {t['n_pairs']} pairs tie"
        interval = _continuous_interval(t)
        interval = f"({interval})" if t["ci95"] is None else interval
        detail = (f"Hodges-Lehmann {t['estimate']:+.3g} {interval}; {test}; {t['n_informative']} of "
                  f"{t['n_pairs']} pairs differ, mean of all {t['mean_diff']:+.3g} "
                  f"({'higher' if t['higher_is_better'] else 'lower'} is better)")
        return t["metric"], t["verdict"], detail
    rates = f"rate A {100 * t['rate_a']:.0f}%, B {100 * t['rate_b']:.0f}%"
    if t["paired"]:
        c = t["pairs"]
        ci = "interval unbounded" if t["ci95"] is None else f"[{_pct(t['ci95'][0])}, {_pct(t['ci95'][1])}]"
        line = (f"{rates}, B - A {_pct(t['mean_diff'])} {ci}; {test}; {t['n_pairs']} "
                f"pairs (both {c['both']}, only A {c['only_a']}, only B {c['only_b']}, neither {c['neither']})")
    else:
        lo, hi = t["ci95"]
        line = (f"{rates}, unpaired ({t['n_a']} vs {t['n_b']} rollouts); "
                f"odds ratio B:A {_odds_estimate(t)} [{_odds(lo)}, {_odds(hi)}]; {test}")
    if t.get("rollouts_needed"):
        line += f"; about {t['rollouts_needed']} rollouts per side would settle it (80% power)"
    elif "rollouts_needed" in t:
        line += "; equal rates: no number of rollouts tells them apart"
    return "success", t["verdict"], line


def verdict_lines(tests: list[Row]) -> list[str]:
    """The text output's last lines: one verdict per metric, with its interval and test."""
    if not tests:
        return []
    return ["Verdicts at 95% (each from its one test: estimate of B - A, the interval inverting the test, "
            "its p):", *(f"  {verdict_text(t)}" for t in tests)]
