from __future__ import annotations

import math

import pytest
import torch

from torchsar.errors import InputTypeError, InputValueError, OptionError, ShapeError
from torchsar.motion import detect_movers, registration_sigma


def _pattern(seed=0, b=1, n=6, p=4, noise=0.01):
    g = torch.Generator().manual_seed(seed)
    base = torch.randn(b, 1, p, 2, generator=g, dtype=torch.float64)
    base[:, :, 0] = 0
    d = base + noise * torch.randn(b, n, p, 2, generator=g, dtype=torch.float64)
    d[:, :, 0] = 0
    return d


class TestDetectMovers:
    def test_flags_the_mover_only(self):
        d = _pattern()
        d[0, 4, 1:, 0] += torch.tensor([0.3, -0.2, 0.25], dtype=torch.float64)
        dec = detect_movers(d, sigma=0.01 * math.sqrt(2))
        assert dec.mover.tolist() == [[False, False, False, False, True, False]]
        assert dec.score[0, 4] > 10

    def test_pattern_is_robust_median(self):
        d = _pattern(noise=0.0)
        d[0, 0] += 5.0  # a wild mover does not move the pattern
        dec = detect_movers(d, sigma=0.01)
        torch.testing.assert_close(dec.pattern[0, 1:], d[0, 1, 1:])
        assert dec.mover[0].tolist() == [True, False, False, False, False, False]

    def test_mad_sigma_when_not_given(self):
        d = _pattern(seed=2, n=40, noise=0.02)
        d[0, 7, 2, 1] += 1.0
        dec = detect_movers(d)
        assert dec.sigma[0, 0, 0, 0] == pytest.approx(0.02, rel=0.35)
        assert dec.mover[0].nonzero().flatten().tolist() == [7]

    def test_missing_measurements_and_min_sigma(self):
        d = _pattern(noise=0.0)
        d[0, 2, 1:] = float("nan")  # seen in one image only: no decision
        d[0, 3, 3] = float("nan")
        d[0, 3, 1, 1] += 0.5
        dec = detect_movers(d, sigma=1e-6, min_sigma=0.05)
        assert math.isnan(float(dec.score[0, 2])) and not dec.mover[0, 2]
        assert dec.mover[0, 3] and float(dec.sigma.min()) == pytest.approx(0.05)

    @pytest.mark.parametrize("b", [0, 1, 2])
    def test_batch_invariance(self, b):
        d = _pattern(b=1)
        d[0, 1, 1, 0] += 0.4
        one = detect_movers(d, sigma=0.02)
        many = detect_movers(d.expand(b, -1, -1, -1), sigma=0.02)
        assert many.mover.shape == (b, 6)
        if b:
            assert torch.equal(many.mover, one.mover.expand(b, -1))

    def test_errors(self):
        with pytest.raises(ShapeError, match=r"\(B, N, P, 2\)"):
            detect_movers(torch.zeros(4, 4, 2))
        with pytest.raises(InputTypeError, match="displacements"):
            detect_movers(torch.zeros(1, 4, 4, 2, dtype=torch.long))
        with pytest.raises(OptionError, match="n_sigma"):
            detect_movers(torch.zeros(1, 4, 4, 2), n_sigma=0)

    @pytest.mark.parametrize("sigma", [0.0, -0.1, float("nan"), torch.tensor([0.1, 0.0])])
    def test_sigma_must_be_positive(self, sigma):
        with pytest.raises(InputValueError, match="sigma must be finite and > 0"):
            detect_movers(torch.zeros(1, 4, 2, 2), sigma=sigma)

    def test_sigma_must_broadcast(self):
        with pytest.raises(ShapeError, match="sigma must broadcast"):
            detect_movers(torch.zeros(1, 4, 2, 2), sigma=torch.ones(3))

    @pytest.mark.parametrize("given", [None, 0.1])
    def test_no_targets_is_an_empty_decision(self, given):
        r = detect_movers(torch.zeros(3, 0, 4, 2), sigma=given)
        assert r.mover.shape == (3, 0) and r.score.shape == (3, 0)
        assert r.residual.shape == (3, 0, 4, 2) and r.pattern.shape == (3, 4, 2)
        assert r.pattern.isnan().all()


class TestRegistrationSigma:
    def test_crlb_formula_and_empirical_scale(self):
        s = registration_sigma(torch.tensor([50.0, 5000.0], dtype=torch.float64), (1.0, 0.3))
        k = math.sqrt(3) / (math.pi * math.sqrt(100))
        torch.testing.assert_close(s[0], torch.tensor([k, 0.3 * k], dtype=torch.float64))
        assert float(s[1, 0]) == pytest.approx(k / 10)
