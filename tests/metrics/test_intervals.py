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


def _t_factor(units: int, count: float | None = None, level: float = 0.95) -> float:
    """Korn & Graubard's factor written out with scipy: (t_{n-1} / t_{units-1})^2, n the
    count (at least the units; None: the normal quantile)."""
    a = (1 - level) / 2
    top = stats.norm.ppf(1 - a) if count is None else stats.t.ppf(1 - a, max(count, units) - 1)
    return (top / stats.t.ppf(1 - a, units - 1)) ** 2


@pytest.mark.parametrize("units", [2, 4, 10, 36, 200])
@pytest.mark.parametrize("count", [None, 1, 36, 37, 700])
def test_t_shrink_is_korn_graubards_factor(units, count):
    assert t_shrink(units, 0.95, count) == pytest.approx(_t_factor(units, count), rel=1e-9)
    assert t_shrink(units, 0.95, count) <= 1.0


@pytest.mark.parametrize("n", [5, 36, 200, 2000])
@pytest.mark.parametrize("x", [0, 1, 3])
def test_one_target_per_image_is_plain_jeffreys(x, n):
    """Independent images with one trial each: the effective count is the real one, the
    Student factor is 1 (count = units: the binomial variance is known from the
    proportion), and the bounds are Jeffreys' (Clopper-Pearson's at 0 and n)."""
    for k in (x, n - x):
        p = k / n
        iv = proportion_interval(p, n, _binomial_spread(p, n), units=n)
        assert (iv.lo, iv.hi) == pytest.approx(_jeffreys(k, n), abs=1e-9), (k, n)


def test_clustered_targets_get_the_student_factor_on_the_effective_count():
    """1000 targets in 10 images with a design effect of 5: Jeffreys on 200 effective
    trials shrunk by (t_999 / t_9)^2."""
    p, count, units = 0.7, 1000, 10
    var = 5 * p * (1 - p) / count * (units - 1) / units
    iv = proportion_interval(p, count, ReplicateSpread(p, var, 1000, 0), units=units)
    m = 200 * _t_factor(units, count)
    assert (iv.lo, iv.hi) == pytest.approx(_jeffreys(p * m, m), abs=1e-9)


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


def _poisson(k: float, kind: str, level: float = 0.95) -> tuple[float, float]:
    """The slow obvious reference: chi-square quantiles (Garwood: 2k and 2k + 2 degrees
    of freedom; Jeffreys: 2k + 1 for both, Garwood's upper bound at 0)."""
    a = (1 - level) / 2
    if kind == "jeffreys" and k > 0:
        return stats.chi2.ppf(a, 2 * k + 1) / 2, stats.chi2.ppf(1 - a, 2 * k + 1) / 2
    lo = 0.0 if k == 0 else stats.chi2.ppf(a, 2 * k) / 2
    return lo, stats.chi2.ppf(1 - a, 2 * k + 2) / 2


def test_zero_false_alarms_is_the_exact_poisson_bound():
    """No false alarm in n independent images: [0, chi2_2(97.5 %) / 2 / n] (3.69 / n), the
    Student factor 1 (count = units)."""
    for n in (10, 36, 400):
        iv = rate_interval(0, n, np.zeros(50))
        assert (iv.lo, iv.hi) == pytest.approx((0.0, stats.chi2.ppf(0.975, 2) / 2 / n), rel=1e-9)


@pytest.mark.parametrize("kind", ["jeffreys", "exact"])
@pytest.mark.parametrize(("n", "total"), [(50, 1), (50, 3), (36, 120), (4, 170)])
def test_poisson_counts_per_image_give_the_poisson_interval(kind, n, total):
    """Independent images with a bootstrap variance exactly Poisson: the Poisson interval
    on the number of images, shrunk by (t_{total-1} / t_{n-1})^2 where the false alarms
    outnumber the images."""
    rate = total / n
    s = ReplicateSpread(rate, rate / n * (n - 1) / n, 1000, 0)
    iv = rate_interval(total, n, s, kind=kind)
    m = n * _t_factor(n, total)
    lo, hi = _poisson(rate * m, kind)
    assert (iv.lo, iv.hi) == pytest.approx((lo / m, hi / m), rel=1e-9)


def test_jeffreys_poisson_is_inside_garwoods():
    """Jeffreys' Poisson interval lies inside Garwood's exact one (which covers at least
    the level for every mean, so is wider) and shares its bounds at zero events."""
    for total in (0, 1, 2, 5, 40):
        s = ReplicateSpread(total / 30, total / 900 * 29 / 30, 1000, 0)
        j, g = rate_interval(total, 30, s), rate_interval(total, 30, s, kind="exact")
        assert g.lo <= j.lo <= j.hi <= g.hi
        assert (j.hi == g.hi) == (total == 0)


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
    for k in (
        "fom",
        "ap50",
        "pd_at_0.1_fa_per_image",
        "pd_at_1_fa_per_image",
        "pd_at_10_fa_per_image",
        "pauc",
    ):
        m[k] = 0.5
    return m


def test_headline_intervals_cover_every_metric_or_say_why_not():
    rng = np.random.default_rng(0)
    m = _metrics()
    reps = {
        k: np.clip(rng.normal(m.get(k, 0.2), 0.03, 200), 0, 1)
        for k in (
            "precision",
            "recall",
            "f1",
            "fom",
            "ap50",
            "pd_at_0.1_fa_per_image",
            "pd_at_1_fa_per_image",
            "pd_at_10_fa_per_image",
            "pauc",
        )
    }
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
