"""Rates with Wilson score intervals, and the exact sign test on paired episodes: the statistics
computed from episode outcomes.

The Wilson interval is used instead of the normal approximation because evaluation cells are
small (5 trials per food and level) and rates are often 0 or 1, where the normal interval
collapses to zero width and claims a certainty ten trials cannot give.
"""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal
from dataclasses import dataclass

Z_95 = 1.959963984540054  # two-sided 95% quantile of the standard normal


@dataclass(frozen=True)
class Rate:
    """`k` of `n` episodes; rate and interval are NaN when there are no episodes (missing, not zero)."""

    k: int
    n: int
    rate: float
    low: float
    high: float

    @property
    def missing(self) -> bool:
        return self.n == 0


def wilson_interval(k: int, n: int, z: float = Z_95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion k/n; (nan, nan) when n == 0."""
    if k < 0 or n < 0 or k > n:
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    if n == 0:
        return math.nan, math.nan
    p = k / n
    z2 = z * z
    denominator = 1.0 + z2 / n
    centre = (p + z2 / (2 * n)) / denominator
    half = (z / denominator) * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    # 0/n and n/n have bounds of exactly 0 and 1; clamping removes the floating-point residue.
    low = 0.0 if k == 0 else max(0.0, centre - half)
    high = 1.0 if k == n else min(1.0, centre + half)
    return low, high


def rate(k: int, n: int) -> Rate:
    low, high = wilson_interval(int(k), int(n))
    return Rate(int(k), int(n), k / n if n else math.nan, low, high)


def percent_digits(value: float) -> str:
    """A fraction as a percent with one decimal, halves rounded up: 5/8 -> "62.5", 1/16 -> "6.3".

    The one rounding rule of every rate the report prints (tables, headline and figure labels);
    a float's binary residue (0.145 is 0.14499...) is removed before rounding.
    """
    scaled = Decimal(repr(100 * value)).quantize(Decimal("1e-12"))
    return str(scaled.quantize(Decimal("0.1"), rounding=ROUND_HALF_UP))


def format_rate(r: Rate, missing: str = "—") -> str:
    """`82.0% [73.3, 88.3] (82/100)`: percent, Wilson 95% interval in percent, counts."""
    if r.missing:
        return missing
    return f"{percent_digits(r.rate)}% [{percent_digits(r.low)}, {percent_digits(r.high)}] ({r.k}/{r.n})"


def format_percent(value: float | None, missing: str = "—") -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return missing
    return f"{percent_digits(value)}%"


def sign_test_p(only_before: int, only_after: int) -> float:
    """Exact two-sided sign test on the discordant pairs (McNemar's exact test): the probability,
    under no change (each discordant pair equally likely either way), of a split at least as
    uneven. 1.0 without discordant pairs."""
    n, k = only_before + only_after, min(only_before, only_after)
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)
