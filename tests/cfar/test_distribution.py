"""Distribution CFARs: fitted quantiles against direct formulas, conventions, shape fits."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import special, stats

import torchsar as ts
from tests.reference.cfar import ring_cells, sample_clutter
from torchsar._checks import OptionError
from torchsar.cfar.distribution import shape_from_spread
from torchsar.cfar.log_t import log_t_exact, log_t_table
from torchsar.cfar.thresholds import ca_factor

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
