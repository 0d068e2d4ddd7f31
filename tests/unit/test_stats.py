"""bench/stats.py against known values (issue 34 item 4): Wilson's interval from its formula
and published figures, McNemar's exact test from the binomial, Wilcoxon's p from scipy's own
example, Holm's adjustment as R's ``p.adjust(method = "holm")`` gives it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench import stats


def wilson_formula(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    p = k / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return mid - half, mid + half


@pytest.mark.parametrize("k,n", [(0, 20), (19, 20), (20, 20), (11, 16), (35, 55)])
def test_wilson_is_the_score_interval(k, n):
    lo, hi = stats.wilson(k, n)
    flo, fhi = wilson_formula(k, n)
    assert lo == pytest.approx(max(flo, 0.0), abs=1e-9) and hi == pytest.approx(min(fhi, 1.0))


def test_wilson_never_collapses_at_the_ends_and_says_so():
    # the figures: 19/20 is [0.76, 0.99] (a percentile bootstrap printed [0.85, 1])
    assert stats.rate([True] * 19 + [False]) == {
        "n": 20, "k": 19, "rate": 0.95, "ci95": [0.764, 0.991], "method": "wilson",
    }  # fmt: skip
    zero, every = stats.rate([False] * 10), stats.rate([True] * 10)
    assert zero["ci95"][0] == 0.0 and zero["ci95"][1] > 0.25  # not [0, 0]
    assert every["ci95"][1] == 1.0 and every["ci95"][0] < 0.75  # not [1, 1]
    assert stats.rate([])["rate"] is None


def test_mcnemar_exact_is_the_binomial_on_the_discordant_pairs():
    # 1 vs 9 discordant pairs: two-sided 2 * P(X <= 1 | n = 10, 1/2) = 22/1024
    assert stats.mcnemar(1, 9) == pytest.approx(22 / 1024)
    assert stats.mcnemar(9, 1) == pytest.approx(22 / 1024)
    assert stats.mcnemar(5, 5) == pytest.approx(1.0)
    assert stats.mcnemar(0, 0) is None
    # concordant pairs do not enter: 0 vs 6 is 2 / 64 whatever else happened
    assert stats.mcnemar(0, 6) == pytest.approx(2 / 64)


def test_signed_rank_is_scipys_with_n_shown():
    # scipy.stats.wilcoxon's documented example (Cushny and Peebles' sleep data differences)
    d = [6, 8, 14, 16, 23, 24, 28, 29, 41, -48, 49, 56, 60, -67, 75]
    out = stats.signed_rank(d)
    assert out["n"] == 15 and out["a_lower"] == 2 and out["a_higher"] == 13
    assert out["p"] == pytest.approx(0.0413, abs=1e-4)
    assert stats.signed_rank([0, 0, 0])["p"] is None and stats.signed_rank([])["n"] == 0


def test_holm_matches_r():
    # R: p.adjust(c(0.01, 0.04, 0.03, 0.005), "holm") -> 0.03 0.06 0.06 0.02
    assert stats.holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    # capped at 1, monotone, None kept and not counted in m
    assert stats.holm([0.5, None, 0.4]) == pytest.approx([0.8, None, 0.8])
    assert stats.holm([]) == []


def test_median_shows_n_and_an_interval_around_it():
    out = stats.median([3.0, None, 1.0, 2.0, 5.0, 4.0], np.random.default_rng(0))
    assert out["n"] == 5 and out["median"] == 3.0
    assert out["ci95"][0] <= 3.0 <= out["ci95"][1]
    assert stats.median([None], np.random.default_rng(0)) == {"n": 0, "median": None, "ci95": None}
