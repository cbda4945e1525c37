"""Intervals from bootstrap spread: references written out with scipy.stats, boundaries,
width against sample size, undefined replicates."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from torchsar.metrics.intervals import (
    MIN_UNITS,
    ReplicateSpread,
    headline_intervals,
    proportion_interval,
    rate_interval,
    spread,
    t_shrink,
)


def _binomial_spread(p: float, n: int) -> ReplicateSpread:
    """A bootstrap spread whose variance is exactly the binomial one of ``n`` independent
    units (the ``units / (units - 1)`` correction undone)."""
    return ReplicateSpread(p, p * (1 - p) / n * (n - 1) / n, 1000, 0)


def _jeffreys(x: float, n: float, level: float = 0.95) -> tuple[float, float]:
    """The slow obvious reference: Jeffreys' beta quantiles, Clopper-Pearson's at 0 and n."""
    a = (1 - level) / 2
    if x <= 0:
        return 0.0, stats.beta.ppf(1 - a, 1, n)
    if x >= n:
        return stats.beta.ppf(a, n, 1), 1.0
    return stats.beta.ppf(a, x + 0.5, n - x + 0.5), stats.beta.ppf(1 - a, x + 0.5, n - x + 0.5)


def _t_factor(units: int, level: float = 0.95) -> float:
    a = (1 - level) / 2
    return (stats.norm.ppf(1 - a) / stats.t.ppf(1 - a, units - 1)) ** 2


@pytest.mark.parametrize("n", [5, 36, 200, 2000])
@pytest.mark.parametrize("x", [0, 1, 3])
def test_one_target_per_image_is_jeffreys_on_the_t_shrunk_count(x, n):
    """Independent images with one trial each: the effective count is the real one, shrunk
    by (z / t_{n-1})^2, and the bounds are Jeffreys' (Clopper-Pearson's at 0 and n)."""
    for k in (x, n - x):
        p = k / n
        iv = proportion_interval(p, n, _binomial_spread(p, n), units=n)
        m = n * _t_factor(n)
        assert (iv.lo, iv.hi) == pytest.approx(_jeffreys(p * m, m), abs=1e-9), (k, n)


@pytest.mark.parametrize("n", [1, 2, 10, 36, 500])
def test_no_zero_width_at_zero_or_at_all_successes(n):
    """A finite sample at 0 or at every success, where every replicate agrees, still gets
    an interval of positive width (never ``[1, 1]`` or ``[0, 0]``) when n >= 2."""
    flat = np.ones(100)
    for point, reps in ((1.0, flat), (0.0, 0 * flat)):
        iv = proportion_interval(point, n, reps, units=n)
        if n == 1:  # one unit says nothing about the spread: no interval
            assert np.isnan(iv.lo) and iv.note
            continue
        assert iv.hi - iv.lo > 0 and iv.lo <= point <= iv.hi
        assert iv.lo >= 0.0 and iv.hi <= 1.0
    fa = rate_interval(0, n, 0 * flat)
    if n > 1:
        assert fa.lo == 0.0 and fa.hi > 0.0


def test_zero_false_alarms_is_the_exact_poisson_bound():
    """No false alarm in n images (independent): the upper bound is Garwood's exact one,
    chi2(2) / 2 at 97.5 %, per t-shrunk image."""
    for n in (10, 36, 400):
        iv = rate_interval(0, n, np.zeros(50))
        m = n * _t_factor(n)
        assert iv.hi == pytest.approx(stats.chi2.ppf(0.975, 2) / 2 / m, rel=1e-9)


def test_poisson_counts_per_image_give_the_exact_poisson_interval():
    """Independent images with a bootstrap variance exactly Poisson: Garwood's interval on
    the t-shrunk number of images."""
    n, total = 50, 120
    rate = total / n
    s = ReplicateSpread(rate, rate / n * (n - 1) / n, 1000, 0)
    iv = rate_interval(total, n, s)
    m = n * _t_factor(n)
    k = rate * m
    lo = stats.chi2.ppf(0.025, 2 * k) / 2 / m
    hi = stats.chi2.ppf(0.975, 2 * (k + 1)) / 2 / m
    assert (iv.lo, iv.hi) == pytest.approx((lo, hi), rel=1e-9)


def test_overdispersion_widens_and_underdispersion_narrows():
    """Correlated images (bootstrap variance above the binomial) widen the interval like a
    smaller sample; anti-correlated ones narrow it."""
    p, n = 0.3, 400
    base = _binomial_spread(p, n)
    wide = proportion_interval(p, n, ReplicateSpread(p, 4 * base.var, 1000, 0), n)
    plain = proportion_interval(p, n, base, n)
    narrow = proportion_interval(p, n, ReplicateSpread(p, base.var / 4, 1000, 0), n)
    w = [iv.hi - iv.lo for iv in (narrow, plain, wide)]
    assert w[0] < w[1] < w[2]
    assert w[2] / w[1] == pytest.approx(2.0, rel=0.05)  # design effect 4: twice as wide


@pytest.mark.parametrize("p", [0.1, 0.5, 0.97])
def test_width_shrinks_like_one_over_sqrt_n(p):
    widths = []
    for n in (400, 1600, 6400):
        iv = proportion_interval(p, n, _binomial_spread(p, n), units=n)
        widths.append(iv.hi - iv.lo)
    assert widths[0] / widths[1] == pytest.approx(2.0, rel=0.05)
    assert widths[1] / widths[2] == pytest.approx(2.0, rel=0.03)
    rates = [rate_interval(2 * n, n, ReplicateSpread(2, 2 / n, 1000, 0)) for n in (400, 1600)]
    assert (rates[0].hi - rates[0].lo) / (rates[1].hi - rates[1].lo) == pytest.approx(2, rel=0.05)


def test_few_units_widen_the_interval_like_student():
    """The same spread from 4 units instead of 400 gives a wider interval (t with 3
    degrees of freedom); one unit gives none."""
    s = ReplicateSpread(0.5, 0.0025, 1000, 0)
    many = proportion_interval(0.5, 100, s, units=400)
    few = proportion_interval(0.5, 100, s, units=4)
    assert few.hi - few.lo > 1.5 * (many.hi - many.lo)
    assert t_shrink(1, 0.95) == 0.0 and np.isnan(proportion_interval(0.5, 100, s, 1).lo)


def test_undefined_replicates_are_counted_and_reported():
    reps = np.array([0.5, np.nan, 0.6, 0.4, np.nan, 0.5])
    s = spread(reps)
    assert (s.used, s.undefined) == (4, 2)
    assert s.var == pytest.approx(np.var([0.5, 0.6, 0.4, 0.5], ddof=1))
    iv = proportion_interval(0.5, 40, reps, units=40)
    assert iv.undefined == 2 and np.isfinite(iv.lo)
    allnan = proportion_interval(0.5, 40, np.full(10, np.nan), units=40)
    assert np.isnan(allnan.lo) and allnan.undefined == 10 and allnan.note


def test_bias_correction_moves_the_centre_against_the_bootstrap_bias():
    """Replicates centred above the point (an upward-biased estimator) pull the corrected
    centre below it, by the bootstrap's bias."""
    s = ReplicateSpread(0.25, 0.001, 1000, 0)
    plain = proportion_interval(0.22, 100, s, 100)
    corrected = proportion_interval(0.22, 100, s, 100, bias_corrected=True)
    assert corrected.centre == pytest.approx(0.19)
    assert corrected.lo < plain.lo and corrected.hi < plain.hi


def _metrics(tp=30, fp=5, n_gt=40):
    m = {"tp": tp, "fp": fp, "fn": n_gt - tp, "precision": tp / (tp + fp), "recall": tp / n_gt}
    m["f1"] = 2 * tp / (2 * tp + fp + n_gt - tp)
    for k in ("fom", "ap50", "pd_at_0.1_fa_per_image", "pd_at_1_fa_per_image",
              "pd_at_10_fa_per_image", "pauc"):  # fmt: skip
        m[k] = 0.5
    return m


def test_headline_intervals_cover_every_metric_or_say_why_not():
    rng = np.random.default_rng(0)
    m = _metrics()
    reps = {k: np.clip(rng.normal(m.get(k, 0.2), 0.03, 200), 0, 1)
            for k in ("precision", "recall", "f1", "fom", "ap50", "pd_at_0.1_fa_per_image",
                      "pd_at_1_fa_per_image", "pd_at_10_fa_per_image", "pauc")}  # fmt: skip
    reps["fa_per_image"] = rng.normal(0.2, 0.05, 200)
    out = headline_intervals(m, reps, units=25, n_gt=40, images_per_km2=4.0)
    for k, iv in out.items():
        if k == "ap50_95":
            assert np.isnan(iv.lo) and iv.note and iv.method == "none"
        else:
            assert iv.lo < iv.hi and not iv.note, k
    fa, km2 = out["fa_per_image"], out["fa_per_km2"]
    assert (km2.lo, km2.hi) == pytest.approx((4 * fa.lo, 4 * fa.hi))
    few = headline_intervals(m, reps, units=MIN_UNITS - 1, n_gt=40)
    assert all(str(MIN_UNITS) in iv.note for k, iv in few.items() if k != "ap50_95")
