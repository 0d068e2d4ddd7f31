"""The statistics of the comparison benches, in one place (issue 34 item 4), each the standard
test for its question and checked against known values (tests/unit/test_stats.py):

- a success rate: its Wilson score interval (``rate``; ``ci95`` never collapses to a point at
  0/n or n/n the way a percentile bootstrap does);
- paired success (two strategies on the same scenario and seed): McNemar's exact test on the
  discordant pairs (``mcnemar``), not a signed-rank test on 0/1;
- paired times or impulses (the runs both delivered): Wilcoxon's signed-rank test with n shown
  (``signed_rank``);
- a median: with its n and a percentile-bootstrap interval (``median``);
- the pairwise tests of one table: Holm's step-down adjustment (``holm``).

scipy computes the tests (``binomtest`` gives Wilson's and the exact binomial; ``wilcoxon``);
Holm's adjustment is a few lines, written here.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.stats import binomtest, wilcoxon

BOOT = 2000  # bootstrap resamples of a median


def wilson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson's score interval of a rate of ``k`` successes in ``n`` runs ((0, 1) when n = 0)."""
    if n == 0:
        return (0.0, 1.0)
    ci = binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
    return (float(ci.low), float(ci.high))


def rate(flags: Sequence[bool]) -> dict:
    """A success rate with its n and 95 % Wilson interval (``method`` names it)."""
    n, k = len(flags), int(sum(bool(f) for f in flags))
    if n == 0:
        return {"n": 0, "k": 0, "rate": None, "ci95": None, "method": "wilson"}
    lo, hi = wilson(k, n)
    return {
        "n": n,
        "k": k,
        "rate": round(k / n, 3),
        "ci95": [round(lo, 3), round(hi, 3)],
        "method": "wilson",
    }


def mcnemar(only_a: int, only_b: int) -> float | None:
    """McNemar's exact test (two-sided) of paired success: ``only_a`` pairs where only A
    succeeded, ``only_b`` where only B did (the concordant pairs carry no information).
    None without discordant pairs."""
    n = only_a + only_b
    if n == 0:
        return None
    return float(binomtest(only_a, n, 0.5).pvalue)


def signed_rank(diffs: Sequence[float]) -> dict:
    """Wilcoxon's signed-rank test (two-sided, zeros split) of paired differences A - B, with
    n and how many favour each side; ``p`` None when every difference is 0 or none."""
    d = np.asarray(diffs, float)
    out = {"n": len(d), "a_lower": int(np.sum(d < 0)), "a_higher": int(np.sum(d > 0))}
    if len(d) == 0 or not np.any(d != 0):
        return {**out, "p": None}
    return {**out, "p": float(wilcoxon(d, zero_method="zsplit").pvalue)}


def median(values: Sequence[float | None], rng: np.random.Generator) -> dict:
    """A median with its n and 95 % percentile-bootstrap interval (None values skipped)."""
    v = np.asarray([x for x in values if x is not None], float)
    if len(v) == 0:
        return {"n": 0, "median": None, "ci95": None}
    meds = np.median(rng.choice(v, size=(BOOT, len(v)), replace=True), axis=1)
    lo, hi = np.percentile(meds, [2.5, 97.5])
    return {
        "n": len(v),
        "median": round(float(np.median(v)), 3),
        "ci95": [round(lo, 3), round(hi, 3)],
    }


def holm(pvalues: Sequence[float | None]) -> list[float | None]:
    """Holm's step-down adjustment of a family of p-values (None kept in place, not counted):
    the i-th smallest of m is multiplied by m - i, made monotone, capped at 1."""
    idx = [i for i, p in enumerate(pvalues) if p is not None]
    m = len(idx)
    out: list[float | None] = [None] * len(pvalues)
    running = 0.0
    for rank, i in enumerate(sorted(idx, key=lambda j: pvalues[j])):  # type: ignore[arg-type,return-value]
        running = max(running, min(1.0, (m - rank) * float(pvalues[i])))  # type: ignore[arg-type]
        out[i] = running
    return out
