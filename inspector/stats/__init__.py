"""Intervals and tests for deciding on an evaluation: is a success rate what it seems, is B better
than A or is the difference noise, and how many rollouts would settle it.

Each function is reproducible from its inputs alone (the bootstrap is seeded) and is checked
against scipy in ``tests/test_stats.py``:

- :func:`wilson_interval`: the Wilson score interval of a binomial proportion (Wilson 1927,
  "Probable inference, the law of succession, and statistical inference", JASA 22), as
  ``scipy.stats.binomtest(k, n).proportion_ci(method="wilson")``.
- :func:`newcombe_interval`: the interval of a difference of two independent proportions built
  from their Wilson intervals (Newcombe 1998, "Interval estimation for the difference between
  independent proportions", Statistics in Medicine 17, method 10).
- :func:`paired_bootstrap`: Efron's percentile bootstrap of the mean of paired differences
  (Efron & Tibshirani 1993, "An Introduction to the Bootstrap", ch. 13), as
  ``scipy.stats.bootstrap(method="percentile")`` with the same generator.
- :func:`signed_rank_test`: Wilcoxon's signed-rank test of paired differences (Wilcoxon 1945,
  "Individual comparisons by ranking methods", Biometrics Bulletin 1), as
  ``scipy.stats.wilcoxon``, with the Hodges-Lehmann shift (Hodges & Lehmann 1963, "Estimates of
  location based on rank tests", Ann. Math. Statist. 34) and the interval that inverts the test.
- :func:`mcnemar_exact`: McNemar's test on paired successes, exact (McNemar 1947): the discordant
  pairs under H0 are Binomial(b + c, 1/2); :func:`mcnemar_interval`: the exact conditional
  interval that inverts it.
- :func:`fisher_exact` / :func:`barnard_exact`: two independent success counts (scipy's tests);
  :func:`fisher_central` with :func:`fisher_odds_ratio`: Fisher's test as twice its smaller tail
  and the exact conditional interval of the odds ratio that inverts it.
- :func:`rollouts_needed`: the rollouts per side at which an observed difference of two rates
  would be significant with a given power (the normal-approximation sample size for two
  proportions, Fleiss, Levin & Paik 2003, "Statistical Methods for Rates and Proportions", eq. 4.14,
  without continuity correction).

Two modules of statistics across sessions, named by module (not re-exported here: their names
overlap): :mod:`.ranking`, Bradley-Terry strengths of checkpoints from pairwise votes with
bootstrap intervals (Bradley & Terry 1952), its fit held to the likelihood's maximum that scipy's
optimiser finds, and its intervals checked for coverage in ``tests/test_ranking_stats.py``; :mod:`.agreement`, how well success in
imagination predicts success for real (Pearson, Spearman, Kendall, SIMPLER's MMRV) with basic
bootstrap intervals, each statistic held to scipy's in ``tests/test_agreement_stats.py``.
"""

from __future__ import annotations

from ._intervals import BOOTSTRAP_RESAMPLES as BOOTSTRAP_RESAMPLES
from ._intervals import BOOTSTRAP_SEED as BOOTSTRAP_SEED
from ._intervals import BootstrapResult as BootstrapResult
from ._intervals import newcombe_interval as newcombe_interval
from ._intervals import paired_bootstrap as paired_bootstrap
from ._intervals import wilson_interval as wilson_interval
from ._signed_rank import TIE_TOLERANCE as TIE_TOLERANCE
from ._signed_rank import SignedRankResult as SignedRankResult
from ._signed_rank import min_pairs_to_reject as min_pairs_to_reject
from ._signed_rank import signed_rank_test as signed_rank_test
from ._tests import ALPHA as ALPHA
from ._tests import NO_DIFFERENCE as NO_DIFFERENCE
from ._tests import TestResult as TestResult
from ._tests import Verdict as Verdict
from ._tests import barnard_exact as barnard_exact
from ._tests import fisher_can_reject as fisher_can_reject
from ._tests import fisher_central as fisher_central
from ._tests import fisher_exact as fisher_exact
from ._tests import fisher_min_per_side as fisher_min_per_side
from ._tests import fisher_odds_ratio as fisher_odds_ratio
from ._tests import mcnemar_exact as mcnemar_exact
from ._tests import mcnemar_interval as mcnemar_interval
from ._tests import rollouts_needed as rollouts_needed
from ._tests import too_few as too_few
from ._tests import verdict_from_test as verdict_from_test

__all__ = [
    "ALPHA", "BOOTSTRAP_RESAMPLES", "BOOTSTRAP_SEED", "NO_DIFFERENCE", "TIE_TOLERANCE", "BootstrapResult",
    "SignedRankResult", "TestResult", "Verdict", "barnard_exact", "fisher_can_reject", "fisher_central",
    "fisher_exact", "fisher_min_per_side", "fisher_odds_ratio", "mcnemar_exact", "mcnemar_interval",
    "min_pairs_to_reject", "newcombe_interval", "paired_bootstrap", "rollouts_needed", "signed_rank_test",
    "too_few", "verdict_from_test", "wilson_interval",
]
