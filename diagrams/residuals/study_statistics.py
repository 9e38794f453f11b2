"""Confidence intervals and tables of a Monte Carlo study (the contact study's figures).

* ``proportion_interval``: the Clopper-Pearson ("exact") interval of a binomial proportion
  (Clopper and Pearson, Biometrika 1934): it never covers less than the level, so a floor
  checked on its lower end holds with at least that confidence.
* ``quantile_interval``: the distribution-free interval of a quantile from order statistics
  (e.g. Conover, "Practical Nonparametric Statistics", 3rd ed., Sec. 3.2): the number of
  samples below the true p-quantile is binomial(n, p), so [x_(j), x_(k)] with j, k from its
  tails covers it with at least the level.
* ``percentile_with_inf``: np.percentile where a value may be inf (a trial without a result).
* ``rate_table``: per group (e.g. per pushed link) the trials, the successes and the rate
  with its interval.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence

import numpy as np
from scipy.stats import beta, binom

#: The level of every interval the study prints.
CONFIDENCE_LEVEL = 0.95


def _check_level(level: float) -> float:
    level = float(level)
    if not 0.0 < level < 1.0:
        raise ValueError(f"the confidence level must be in (0, 1), got {level}")
    return level


def proportion_interval(successes: int, trials: int, level: float = CONFIDENCE_LEVEL) -> tuple[float, float]:
    """Clopper-Pearson interval of successes / trials (two-sided, ``level``).

    Raises:
        ValueError: trials < 1, successes outside [0, trials], a level outside (0, 1).
    """
    level = _check_level(level)
    if int(trials) != trials or trials < 1 or int(successes) != successes or not 0 <= successes <= trials:
        raise ValueError(f"need 0 <= successes <= trials and trials >= 1, got {successes} of {trials}")
    alpha = 1.0 - level
    lower = 0.0 if successes == 0 else float(beta.ppf(alpha / 2.0, successes, trials - successes + 1))
    upper = 1.0 if successes == trials else float(beta.ppf(1.0 - alpha / 2.0, successes + 1, trials - successes))
    return lower, upper


def quantile_interval(values: Sequence[float], p: float, level: float = CONFIDENCE_LEVEL) -> tuple[float, float]:
    """Distribution-free interval of the ``p``-quantile of the distribution ``values`` were
    drawn from (order statistics; ``inf`` values allowed, e.g. a failed trial's error). An
    end that the sample is too small to bound is -inf or inf.

    Raises:
        ValueError: no values, NaN among them, p outside (0, 1), a level outside (0, 1).
    """
    level = _check_level(level)
    x = np.sort(np.asarray(values, dtype=float).reshape(-1))
    if x.size == 0 or np.isnan(x).any():
        raise ValueError("quantile_interval needs at least one value and no NaN")
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must be in (0, 1), got {p}")
    n, alpha = x.size, 1.0 - level
    # B ~ binom(n, p) samples lie below the quantile Q_p; x_(j) > Q_p iff B < j and
    # x_(k) < Q_p iff B >= k. j: the largest with P(B <= j - 1) < alpha/2 (binom.ppf gives
    # the smallest m with P(B <= m) >= alpha/2); k: the smallest with P(B >= k) <= alpha/2.
    j = int(binom.ppf(alpha / 2.0, n, p))
    k = int(binom.isf(alpha / 2.0, n, p)) + 1
    lower = x[j - 1] if j >= 1 else -math.inf
    upper = x[k - 1] if k <= n else math.inf
    return float(lower), float(upper)


def percentile_with_inf(values: np.ndarray, q: float) -> float:
    """np.percentile of values that may hold inf (a trial without a localization): where it
    interpolates between two infs the answer is inf, not the NaN (and warning) of inf - inf."""
    with np.errstate(invalid="ignore"):
        value = float(np.percentile(values, q))
    return math.inf if math.isnan(value) else value


def rate_table(
    items: Iterable[dict],
    group: Callable[[dict], str],
    success: Callable[[dict], bool],
    level: float = CONFIDENCE_LEVEL,
) -> list[dict]:
    """Per group (``group(item)``): ``{"group", "trials", "successes", "rate", "interval"}``,
    sorted by rate, then by group name (the worst groups first)."""
    counts: dict[str, list[int]] = {}
    for item in items:
        c = counts.setdefault(group(item), [0, 0])
        c[0] += 1
        c[1] += bool(success(item))
    rows = [
        {"group": g, "trials": t, "successes": s, "rate": s / t, "interval": list(proportion_interval(s, t, level))}
        for g, (t, s) in counts.items()
    ]
    return sorted(rows, key=lambda row: (row["rate"], row["group"]))


__all__ = ["CONFIDENCE_LEVEL", "proportion_interval", "quantile_interval", "rate_table"]
