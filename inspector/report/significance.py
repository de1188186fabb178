"""Is the difference between A and B real? One test per compared metric, each with the interval of
the difference, a p-value and a verdict at 95% (``compare``'s ``tests``).

- Continuous metrics, over the pairs with a value on both sides: the mean difference B - A, its
  percentile bootstrap interval (:func:`inspector.stats.paired_bootstrap`, seeded, 10,000
  resamples) and the Wilcoxon signed-rank p. The verdict follows the interval: a side is better
  only when the whole interval is on its side.
- Success: over the pairs with a success flag on both sides, McNemar's exact test on the discordant
  pairs (the interval: the paired bootstrap of the per-pair difference); with no such pair, Fisher's
  exact test on the two sides' success counts (the interval: Newcombe's, from the two Wilson
  intervals). The verdict follows the test. When it is not significant, ``rollouts_needed`` says
  how many rollouts per side would make the observed rates' difference significant with 80% power.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from ..stats import (
    BOOTSTRAP_RESAMPLES,
    fisher_exact,
    mcnemar_exact,
    newcombe_interval,
    paired_bootstrap,
    rollouts_needed,
    verdict_from_interval,
    verdict_from_test,
)

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


def _wilcoxon_p(d: np.ndarray) -> float | None:
    from scipy import stats

    nonzero = d[np.abs(d) > 1e-9]
    if not nonzero.size:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = float(stats.wilcoxon(nonzero).pvalue)
    return p if math.isfinite(p) else None


def continuous_test(metric: str, pairs: list[tuple[Row, Row]], get: Getter, higher_is_better: bool) -> Row | None:
    values = [(a, b) for a, b in ((get(pa), get(pb)) for pa, pb in pairs) if a is not None and b is not None]
    if not values:
        return None
    d = np.array([b - a for a, b in values], dtype=np.float64)
    boot = paired_bootstrap(d)
    return {"metric": metric, "n_pairs": int(d.size), "mean_diff": boot.mean, "ci95": list(boot.ci),
            "p": _wilcoxon_p(d), "test": f"wilcoxon; bootstrap {BOOTSTRAP_RESAMPLES} resamples",
            "verdict": verdict_from_interval(boot.ci, higher_is_better), "higher_is_better": higher_is_better}


def success_test(pairs: list[tuple[Row, Row]], rows_a: list[Row], rows_b: list[Row]) -> Row | None:
    """Paired (McNemar exact) over the pairs with a success flag on both sides, else unpaired
    (Fisher exact) over each side's rows with one; None when a side has none."""
    both = [(sa, sb) for sa, sb in ((_success(a), _success(b)) for a, b in pairs) if sa is not None and sb is not None]
    if both:
        a_only = sum(sa and not sb for sa, sb in both)
        b_only = sum(sb and not sa for sa, sb in both)
        n = len(both)
        rate_a, rate_b = sum(sa for sa, _ in both) / n, sum(sb for _, sb in both) / n
        d = np.array([float(sb) - float(sa) for sa, sb in both])
        ci = paired_bootstrap(d).ci
        result = mcnemar_exact(a_only, b_only)
        record: Row = {"metric": "success", "n_pairs": n, "mean_diff": rate_b - rate_a, "ci95": list(ci),
                       "p": result.pvalue, "test": result.test,
                       "verdict": verdict_from_test(result.pvalue, rate_b - rate_a, True),
                       "higher_is_better": True, "n_a": n, "n_b": n, "rate_a": rate_a, "rate_b": rate_b,
                       "discordant": {"a_only": a_only, "b_only": b_only}}
    else:
        flags_a = [s for s in map(_success, rows_a) if s is not None]
        flags_b = [s for s in map(_success, rows_b) if s is not None]
        if not flags_a or not flags_b:
            return None
        sa, na, sb, nb = sum(flags_a), len(flags_a), sum(flags_b), len(flags_b)
        rate_a, rate_b = sa / na, sb / nb
        result = fisher_exact(sa, na, sb, nb)
        record = {"metric": "success", "n_pairs": 0, "mean_diff": rate_b - rate_a,
                  "ci95": list(newcombe_interval(sa, na, sb, nb)), "p": result.pvalue, "test": result.test,
                  "verdict": verdict_from_test(result.pvalue, rate_b - rate_a, True),
                  "higher_is_better": True, "n_a": na, "n_b": nb, "rate_a": rate_a, "rate_b": rate_b}
    if record["verdict"] == "no significant difference":
        record["rollouts_needed"] = rollouts_needed(rate_a, rate_b)
    return record


def metric_tests(pairs: list[tuple[Row, Row]], rows_a: list[Row], rows_b: list[Row]) -> list[Row]:
    """``tests``: ``[{metric, n_pairs, mean_diff, ci95, p, test, verdict, ...}]`` for every metric
    with values on both sides (differences B - A)."""
    tests = [t for name, get, higher in continuous_metrics([*rows_a, *rows_b])
             if (t := continuous_test(name, pairs, get, higher)) is not None]
    success = success_test(pairs, rows_a, rows_b)
    return [*tests, *([success] if success is not None else [])]


def _pct(v: float) -> str:
    return f"{100 * v:+.0f}%"


def verdict_lines(tests: list[Row]) -> list[str]:
    """The text output's last lines: one verdict per metric, with its interval and test."""
    if not tests:
        return []
    lines = ["Verdicts at 95% (difference B - A, its 95% interval, the test):"]
    for t in tests:
        lo, hi = t["ci95"]
        p = "-" if t["p"] is None else format(t["p"], ".3g")
        if t["metric"] == "success":
            how = f"{t['n_pairs']} pairs" if t["n_pairs"] else f"{t['n_a']} vs {t['n_b']} rollouts, unpaired"
            line = (f"  success: {t['verdict']}: rate A {100 * t['rate_a']:.0f}%, B {100 * t['rate_b']:.0f}%, "
                    f"B - A {_pct(t['mean_diff'])} [{_pct(lo)}, {_pct(hi)}]; {t['test']} p {p}; {how}")
            if t.get("rollouts_needed"):
                line += f"; about {t['rollouts_needed']} rollouts per side would settle it (80% power)"
            elif "rollouts_needed" in t:
                line += "; equal rates: no number of rollouts tells them apart"
        else:
            line = (f"  {t['metric']}: {t['verdict']}: {t['mean_diff']:+.3g} [{lo:+.3g}, {hi:+.3g}]; "
                    f"Wilcoxon p {p}; {t['n_pairs']} pairs "
                    f"({'higher' if t['higher_is_better'] else 'lower'} is better)")
        lines.append(line)
    return lines
