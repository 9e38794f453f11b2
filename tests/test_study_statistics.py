"""diagrams.residuals.study_statistics: closed forms and simulated coverage."""

import math

import numpy as np
import pytest

from diagrams.residuals.study_statistics import proportion_interval, quantile_interval, rate_table


def test_proportion_interval_closed_forms():
    # With no success the exact upper end solves (1 - p)^n = alpha / 2; with all, symmetrically.
    lower, upper = proportion_interval(0, 10)
    assert lower == 0.0 and upper == pytest.approx(1.0 - 0.025 ** (1 / 10), rel=1e-9)
    lower, upper = proportion_interval(10, 10)
    assert upper == 1.0 and lower == pytest.approx(0.025 ** (1 / 10), rel=1e-9)
    lower, upper = proportion_interval(970, 1000)
    assert lower < 0.97 < upper and 0.955 < lower < 0.96  # the 97 % of 1000 trials
    with pytest.raises(ValueError, match="successes <= trials"):
        proportion_interval(11, 10)
    with pytest.raises(ValueError, match="confidence level"):
        proportion_interval(1, 10, level=1.0)


def test_proportion_interval_covers_at_least_its_level():
    rng = np.random.default_rng(1)
    for p, n in ((0.97, 1000), (0.5, 40), (0.995, 300)):
        hits = [proportion_interval(k, n)[0] <= p <= proportion_interval(k, n)[1] for k in rng.binomial(n, p, 2000)]
        assert np.mean(hits) >= 0.94, (p, n)  # 0.95 minus Monte Carlo slack (2000 draws: std 0.005)


def test_quantile_interval_order_statistics():
    x = np.arange(1.0, 101.0)  # x_(i) = i
    assert quantile_interval(x, 0.5) == (40.0, 61.0)  # the textbook 95 % interval of a median, n = 100
    lower, upper = quantile_interval(x[:10], 0.95)
    assert upper == math.inf and lower <= 10.0  # ten samples cannot bound a 95th percentile from above
    assert quantile_interval([1.0, 2.0, math.inf, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0], 0.5)[1] < math.inf
    with pytest.raises(ValueError, match="NaN"):
        quantile_interval([1.0, math.nan], 0.5)
    with pytest.raises(ValueError, match="p must be"):
        quantile_interval([1.0, 2.0], 1.0)


def test_quantile_interval_covers_at_least_its_level():
    rng = np.random.default_rng(2)
    for p in (0.5, 0.95):
        true_quantile = -math.log(1.0 - p)  # of the unit exponential
        hits = []
        for _ in range(2000):
            lower, upper = quantile_interval(rng.exponential(size=200), p)
            hits.append(lower <= true_quantile <= upper)
        assert np.mean(hits) >= 0.94, p


def test_rate_table_lists_the_worst_groups_first():
    items = [{"link": "a", "ok": True}] * 3 + [{"link": "b", "ok": False}, {"link": "b", "ok": True}]
    rows = rate_table(items, lambda i: i["link"], lambda i: i["ok"])
    assert [r["group"] for r in rows] == ["b", "a"]
    assert (rows[0]["trials"], rows[0]["successes"], rows[0]["rate"]) == (2, 1, 0.5)
    assert rows[1]["interval"][1] == 1.0 and rows[1]["interval"][0] == pytest.approx(0.025 ** (1 / 3))
