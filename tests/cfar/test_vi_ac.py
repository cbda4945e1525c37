"""VI and AC CFAR: decisions, censoring, equality with CA where they reduce to it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import torchsar as ts
from tests.reference.cfar import block_cells, ring_cells
from torchsar.cfar.ac import global_censor_threshold
from torchsar.cfar.thresholds import block_factor, ca_factor
from torchsar.errors import OptionError, ShapeError


@pytest.fixture(scope="module")
def clutter() -> torch.Tensor:
    return torch.empty(1, 1, 96, 96).exponential_(generator=torch.Generator().manual_seed(5))


@pytest.mark.parametrize("name", ["vi", "ac"])
class TestCommon:
    def test_smoke_and_mask_rule(self, clutter, name):
        d = getattr(ts.cfar, name)(clutter)
        assert d.mask.shape == clutter.shape
        assert torch.equal(d.mask, d.statistic > d.threshold)
        assert d.threshold.item() == pytest.approx(ca_factor(144, 1e-3))

    @pytest.mark.parametrize("b", [0, 1, 2])
    def test_batch_invariance(self, name, b):
        x = torch.rand(b, 2, 20, 22, generator=torch.Generator().manual_seed(b))
        fn = getattr(ts.cfar, name)
        d = fn(x, guard=1, train=2)
        for i in range(b):
            torch.testing.assert_close(
                d.statistic[i : i + 1], fn(x[i : i + 1], guard=1, train=2).statistic
            )

    def test_exceptions(self, name):
        fn = getattr(ts.cfar, name)
        with pytest.raises(ShapeError):
            fn(torch.rand(1, 16, 16))
        with pytest.raises(OptionError):
            fn(torch.rand(1, 1, 16, 16), pfa=0.0)

    def test_non_contiguous(self, name):
        fn = getattr(ts.cfar, name)
        x = torch.rand(1, 1, 24, 20, dtype=torch.float64).transpose(-1, -2)
        torch.testing.assert_close(
            fn(x, guard=1, train=2).statistic, fn(x.contiguous(), guard=1, train=2).statistic
        )


class TestVI:
    def test_equals_ca_when_ca_is_always_selected(self, clutter):
        d = ts.cfar.vi(clutter, k_vi=1e9, k_mr=1e9)
        assert torch.equal(d.statistic, ts.cfar.ca(clutter).statistic)
        assert torch.equal(d.mask, ts.cfar.ca(clutter).mask)

    def test_mostly_ca_in_homogeneous_clutter(self, clutter):
        same = ts.cfar.vi(clutter).statistic == ts.cfar.ca(clutter).statistic
        assert same.double().mean().item() > 0.95

    def test_clutter_edge_selects_go(self):
        # left half bright (mean 10), right half dark: at the edge the halves A (top+right) and
        # B (bottom+left) differ in mean but each is fairly uniform -> GO of the half means
        img = np.ones((30, 30))
        img[:, :15] = 10.0
        x = torch.from_numpy(img)[None, None]
        i, j = 15, 15
        d = ts.cfar.vi(x, guard=1, train=3, k_vi=1e9, k_mr=1.5)
        blocks = block_cells(img, i, j, 1, 3)
        a, b = np.concatenate(blocks[:2]), np.concatenate(blocks[2:])
        ref = (
            img[i, j]
            / max(a.mean(), b.mean())
            * ca_factor(72, 1e-3)
            / block_factor((36, 36), 1e-3, "max")
        )
        assert d.statistic[0, 0, i, j].item() == pytest.approx(ref, rel=1e-10)

    def test_variable_half_selects_other_half(self):
        img = np.ones((30, 30))
        img[10, 19] = 500.0  # one interferer in the right block (half A) of pixel (12, 15)
        x = torch.from_numpy(img)[None, None]
        d = ts.cfar.vi(x, guard=1, train=3)
        b = np.concatenate(block_cells(img, 12, 15, 1, 3)[2:])
        ref = img[12, 15] / b.mean() * ca_factor(72, 1e-3) / ca_factor(36, 1e-3)
        assert d.statistic[0, 0, 12, 15].item() == pytest.approx(ref, rel=1e-10)


class TestAC:
    def test_censored_ring_reference(self):
        rng = np.random.default_rng(9)
        img = rng.exponential(size=(40, 40))
        img[18:21, 18:21] = 80.0  # a target cluster
        x = torch.from_numpy(img)[None, None]
        d = ts.cfar.ac(x, guard=1, train=3)
        _, thr = global_censor_threshold(x, 1e-3)
        keep = img <= thr.item()
        i, j = 16, 22  # the cluster sits in this pixel's ring
        cells = ring_cells(np.where(keep, img, np.nan), i, j, 1, 3)
        cells = cells[~np.isnan(cells)]
        ref = img[i, j] / cells.mean() * ca_factor(72, 1e-3) / ca_factor(len(cells), 1e-3)
        assert len(cells) < 72
        assert d.statistic[0, 0, i, j].item() == pytest.approx(ref, rel=1e-10)

    def test_global_threshold_unbiased_on_exponential(self):
        x = (
            torch.empty(2, 1, 300, 300).exponential_(generator=torch.Generator().manual_seed(1))
            * 3.0
        )
        mu, thr = global_censor_threshold(x, 1e-2)
        torch.testing.assert_close(
            mu.flatten(), torch.full((2,), 3.0, dtype=torch.float64), rtol=0.02, atol=0
        )
        torch.testing.assert_close(thr, mu * np.log(100.0))

    def test_fully_censored_ring_uses_global_mean(self):
        img = np.random.default_rng(0).exponential(size=(60, 60))
        img[20:31, 20:31] = 1000.0  # a large target: rings inside it are fully censored
        d = ts.cfar.ac(torch.from_numpy(img)[None, None], guard=1, train=2)
        assert torch.isfinite(d.statistic[0, 0, 25, 25])
        assert d.mask[0, 0, 25, 25].item()

    def test_censor_pfa_validated(self):
        with pytest.raises(OptionError, match="censor_pfa"):
            ts.cfar.ac(torch.rand(1, 1, 16, 16), censor_pfa=2.0)


@pytest.mark.parametrize("masked", [False, True])
def test_vi_every_pixel_equals_reference(masked):
    """Interior, border band and masked-out cells: each pixel's rule, estimate and factor."""
    from tests.reference.cfar import vi_statistic

    rng = np.random.default_rng(3)
    img = rng.exponential(size=(2, 17, 19))
    img[:, 4:8, 5:9] *= 20.0  # variable halves near the bright patch
    valid = rng.random(img.shape) > 0.15 if masked else np.ones(img.shape, bool)
    x = torch.from_numpy(img)[:, None]
    vm = torch.from_numpy(valid)[:, None] if masked else None
    got = ts.cfar.vi(x, guard=1, train=2, k_vi=2.0, k_mr=1.5, valid=vm).statistic[:, 0].numpy()
    for b in range(2):
        for i in range(17):
            for j in range(19):
                if valid[b, i, j]:
                    want = vi_statistic(img[b], valid[b], i, j, 1, 2, 1e-3, 2.0, 1.5)
                    assert got[b, i, j] == pytest.approx(want, rel=1e-9), (b, i, j)


@pytest.mark.parametrize("iterations", [0, 1, 3])
def test_the_compiled_clutter_mean_is_the_tensor_codes(monkeypatch, iterations):
    """The compiled global pre-threshold (one pass per re-estimation, eight running sums)
    and the tensor code's masked means agree to summation rounding."""
    from torchsar import _jit

    g = torch.Generator().manual_seed(4)
    x = torch.empty(3, 2, 37, 41).exponential_(generator=g)
    x[0, 0, 5:15, 5:15] *= 300.0
    x[2, 1] = 0.0
    out = []
    for on in (True, False):
        monkeypatch.setattr(_jit, "ENABLED", on)
        out.append(global_censor_threshold(x, 1e-3, iterations=iterations))
    for a, b in zip(*out, strict=True):
        assert a.shape == b.shape == (3, 2, 1, 1) and a.dtype == b.dtype == torch.float64
        torch.testing.assert_close(a, b, rtol=1e-13, atol=0)
