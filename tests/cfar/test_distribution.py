"""Distribution CFARs: fitted quantiles against direct formulas, conventions, shape fits."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import special, stats

import torchsar as ts
from tests.reference.cfar import ring_cells, sample_clutter
from torchsar.cfar.distribution import shape_from_spread
from torchsar.cfar.log_t import log_t_exact, log_t_table
from torchsar.cfar.thresholds import ca_factor
from torchsar.errors import OptionError

NAMES = ["lognormal", "weibull", "gamma", "k", "g0"]


@pytest.mark.parametrize("name", NAMES)
class TestCommon:
    def test_smoke_threshold_one(self, name):
        x = torch.rand(1, 1, 24, 24) + 0.1
        d = getattr(ts.cfar, name)(x, guard=1, train=2)
        assert d.threshold.item() == 1.0
        assert torch.equal(d.mask, d.statistic > d.threshold)

    @pytest.mark.parametrize("b", [0, 1, 2])
    def test_batch_invariance(self, name, b):
        fn = getattr(ts.cfar, name)
        x = torch.rand(b, 2, 18, 20, generator=torch.Generator().manual_seed(b)) + 0.05
        d = fn(x, guard=1, train=2)
        for i in range(b):
            torch.testing.assert_close(
                d.statistic[i : i + 1], fn(x[i : i + 1], guard=1, train=2).statistic
            )

    def test_bad_pfa(self, name):
        with pytest.raises(OptionError, match="pfa"):
            getattr(ts.cfar, name)(torch.rand(1, 1, 16, 16), pfa=-1.0)

    def test_zeros_are_finite(self, name):
        x = torch.rand(1, 1, 20, 20)
        x[0, 0, 3:6, 3:6] = 0.0
        d = getattr(ts.cfar, name)(x, guard=1, train=2)
        assert not torch.isnan(d.statistic).any()


def _interior(img, fn, i, j, **kw):
    return (
        fn(torch.from_numpy(img)[None, None], guard=1, train=2, **kw).statistic[0, 0, i, j].item()
    )


def test_lognormal_is_student_prediction_bound():
    img = np.random.default_rng(0).lognormal(size=(15, 15))
    cells = np.log(ring_cells(img, 7, 7, 1, 2))
    q = math.exp(
        cells.mean() + cells.std(ddof=1) * stats.t.ppf(1 - 1e-3, 39) * math.sqrt(1 + 1 / 40)
    )
    assert _interior(img, ts.cfar.lognormal, 7, 7) == pytest.approx(img[7, 7] / q, rel=1e-9)


def test_gamma_mask_equals_ca_with_looks():
    x = torch.from_numpy(sample_clutter("gamma", (1, 1, 64, 64), 3, looks=3.0))
    torch.testing.assert_close(ts.cfar.gamma(x, looks=3.0).mask, ts.cfar.ca(x, looks=3.0).mask)
    img = x[0, 0].numpy()
    ref = img[30, 30] / (ring_cells(img, 30, 30, 2, 4).mean() * ca_factor(144, 1e-3, 3.0))
    assert ts.cfar.gamma(x, looks=3.0).statistic[0, 0, 30, 30].item() == pytest.approx(
        ref, rel=1e-9
    )


def test_weibull_log_t_threshold():
    img = sample_clutter("weibull", (15, 15), 1)
    cells = np.log(ring_cells(img, 7, 7, 1, 2))
    t = log_t_table("weibull", 1.0, 1e-3, 40)[0]
    q = math.exp(cells.mean() + t * cells.std(ddof=1))
    assert _interior(img, ts.cfar.weibull, 7, 7) == pytest.approx(img[7, 7] / q, rel=1e-9)


def test_weibull_t_large_n_is_plugin_quantile():
    # n -> inf: t = sqrt(6)/pi (gamma_E + ln ln 1/pfa), the plug-in Weibull quantile
    t = log_t_exact("weibull", 1.0, 1e-4, 10**9)[0]
    assert t == pytest.approx(
        math.sqrt(6) / math.pi * (np.euler_gamma + math.log(math.log(1e4))), rel=1e-3
    )


@pytest.mark.parametrize("shape", [0.2, 1.0, 3.0, 40.0])
def test_shape_from_spread_inverts_trigamma(shape):
    y = torch.tensor([float(special.polygamma(1, shape))], dtype=torch.float64)
    assert shape_from_spread(y).item() == pytest.approx(shape, rel=1e-4)


LOG_NAMES = ["lognormal", "weibull", "k", "g0"]


def _quantised_k_scene() -> tuple[torch.Tensor, torch.Tensor]:
    """K clutter as an 8-bit magnitude image (about 3 % exact zeros, 20 grey levels)
    with a 3x3 bright target at (32, 32) and one at (96, 64)."""
    x = torch.from_numpy(sample_clutter("k", (1, 1, 128, 128), 5))
    amp = (x.sqrt() * 4.0).round().clamp(max=255.0)
    for r, c in ((32, 32), (96, 64)):
        amp[0, 0, r - 1 : r + 2, c - 1 : c + 2] = 255.0
    return ((amp / 255.0) ** 2).float(), amp


@pytest.mark.parametrize("name", LOG_NAMES)
def test_quantised_zeros_are_censored(name):
    """Regression: one exact zero in a ring used to inflate the log-variance (ln 0 clamped to
    -87), so nothing was ever detected on 8-bit data."""
    x, amp = _quantised_k_scene()
    assert 0.01 < (amp == 0).double().mean().item() < 0.1
    d = getattr(ts.cfar, name)(x)
    assert not torch.isnan(d.statistic).any()
    assert torch.equal(d.mask, d.statistic > d.threshold)
    assert d.mask[0, 0, 32, 32] and d.mask[0, 0, 96, 64]
    clutter = d.mask.clone()
    clutter[..., 30:35, 30:35] = False
    clutter[..., 94:99, 62:67] = False
    assert clutter.double().mean().item() < 1e-2  # the clutter is not flooded either
    zero = amp == 0
    assert (d.statistic[zero] == 0).all()  # a zero cell under test is tested: 0 / q


@pytest.mark.parametrize("name", LOG_NAMES)
def test_zeros_leave_the_fit(name):
    """The fit with zeros present equals the fit with those cells marked invalid (the CUT
    aside: a zero CUT has statistic 0, an invalid one -inf)."""
    x = torch.rand(1, 1, 24, 24, generator=torch.Generator().manual_seed(3)) + 0.05
    x[0, 0, 5, 7] = x[0, 0, 12, 11] = 0.0
    fn = getattr(ts.cfar, name)
    a = fn(x, guard=1, train=2).statistic
    b = fn(x, guard=1, train=2, valid=x > 0).statistic
    keep = x > 0
    torch.testing.assert_close(a[keep], b[keep], rtol=1e-6, atol=0.0)


def _mstar_chips(root, n: int) -> list[tuple[torch.Tensor, torch.Tensor]]:
    from skimage import io

    out = []
    for path in sorted((root / "mstar_sarbake").glob("*/*.mask.png"))[::40][:n]:
        img = path.with_name(path.name.replace(".mask.png", ".jpeg"))
        amp = io.imread(img).astype(np.float64)
        lab = io.imread(path)
        out.append((torch.from_numpy((amp / 255.0) ** 2)[None, None], torch.from_numpy(lab == 1)))
    return out


@pytest.mark.parametrize("name", ["weibull", "k"])
def test_real_mstar_chips_detect(data_dir, name):
    """Regression on real 8-bit chips (about 1.5 % zeros, 4 in 5 rings hold one): the
    distribution CFARs detected nothing; now each chip's target is hit (large window so the
    ring sits off the target), with no NaN."""
    for x, target in _mstar_chips(data_dir, 5):
        d = getattr(ts.cfar, name)(x.float(), guard=10, train=6)
        assert not torch.isnan(d.statistic).any()
        assert d.mask[0, 0][target].any()


def _weibull_realised_pfa(pfa: float, n: int, rings: int = 50_000) -> float:
    """Monte-Carlo false-alarm rate of the log-t test on rings of ``n`` exponential cells
    (Weibull c = 1; the standardised log-law is the same for every c): the mean over rings
    of the exact survival ``exp(-q)`` of the threshold ``q = exp(k1 + t sqrt(k2))``."""
    t = log_t_table("weibull", 1.0, pfa, n)[0]
    logs = np.log(np.random.default_rng(n).exponential(size=(rings, n)))
    q = np.exp(logs.mean(1) + t * logs.std(1, ddof=1))
    return float(np.exp(-q).mean())


@pytest.mark.parametrize("pfa", [1e-2, 1e-3])
@pytest.mark.parametrize("n", [144, 200, 384])
def test_log_t_table_holds_pfa_at_ring_sizes(pfa, n):
    assert _weibull_realised_pfa(pfa, n) == pytest.approx(pfa, rel=0.15)


@pytest.mark.parametrize("pfa", [1e-2, 1e-3])
@pytest.mark.parametrize("n", [5, 8, 12, 20, 40, 64, 96])
def test_log_t_table_small_rings_never_exceed_pfa(pfa, n):
    # border pixels have small rings (a corner of the g=2, t=4 ring counts 40 cells)
    assert _weibull_realised_pfa(pfa, n) <= 1.1 * pfa


@pytest.mark.xfail(
    strict=True,
    reason="known: the O(1/n) log-t calibration is conservative "
    "for small rings (about 0.1x the design rate at n = 20, Pfa 1e-3)",
)
def test_log_t_table_small_ring_rate_is_close_to_design():
    assert _weibull_realised_pfa(1e-3, 20) == pytest.approx(1e-3, rel=0.5)
