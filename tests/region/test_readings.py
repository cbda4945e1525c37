"""Hand-made cases for the rules of steps g–i and for each reading of the text."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchsar.region import PRESETS, RegionParams, region_search


def _textured(h: int, w: int) -> torch.Tensor:
    """A mildly textured background (1.0 / 1.2 checkerboard) that grows into flat regions."""
    ii, jj = np.mgrid[:h, :w]
    return torch.from_numpy(1.0 + 0.2 * ((ii + jj) % 2))[None, None]


def _row_of(result, seed):
    return next(r for r in result.tables[0].rows if r.seed == seed)


@pytest.mark.usefixtures("path")
class TestMinimumBackground:
    def _case(self, **kw):
        x = _textured(9, 9)
        x[..., 2:7, 2:7] = 10.0  # 5x5 target; guard 1 -> K is 7x7, ring 1 -> C has 81 - 49 = 32
        return region_search(x, preset="paper", despeckle=None, guard=1, background=1, **kw)

    def test_enough(self):
        row = _row_of(self._case(min_background=32), (2, 2))
        assert row.n_background == 32 and row.accepted

    def test_too_few(self):
        r = self._case(min_background=33)
        row = _row_of(r, (2, 2))
        assert not row.accepted and row.reason == "few_background"
        assert row.statistic == -np.inf
        assert bool((r.detection.statistic[0, 0, 2:7, 2:7] == -np.inf).all())


@pytest.mark.usefixtures("path")
class TestFinalTest:
    def test_hand_computed_statistic(self):
        x = torch.ones(1, 1, 9, 9, dtype=torch.float64)
        x[..., ::2, :] = 3.0  # background rows alternate 3, 1, 3, ...
        x[..., 3:6, 3:6] = 6.0
        r = region_search(x, preset="paper", despeckle=None, guard=1, background=1)
        row = _row_of(r, (3, 3))
        # ring = Chebyshev distance 2 from the 3x3 block: rows 1 and 7 (value 1, 7 cells
        # each) and columns 1, 7 of rows 2..6 (rows 2, 4, 6 -> 3; rows 3, 5 -> 1)
        vals = np.array([1.0] * 14 + [3.0] * 6 + [1.0] * 4)
        assert row.n_background == 24
        assert row.mu_c == pytest.approx(vals.mean()) and row.sigma_c == pytest.approx(vals.std())
        z = (6.0 - vals.mean()) / vals.std()
        assert row.statistic == pytest.approx(z)
        assert row.accepted == (z > 0.25)
        kept = region_search(x, preset="paper", despeckle=None, guard=1, background=1, k=z + 0.1)
        assert not _row_of(kept, (3, 3)).accepted


@pytest.mark.usefixtures("path")
class TestTargetsNeverInLaterBackground:
    def test_earlier_target_censored(self):
        x = _textured(12, 16)
        x[..., 3:7, 2:5] = 100.0  # target A (brightest seed, accepted first)
        x[..., 3:7, 7:10] = 50.0  # target B: its ring (guard 1, width 3) reaches into A
        r = region_search(x, preset="paper", despeckle=None, guard=1, lowpass=None)
        a, b = _row_of(r, (3, 2)), _row_of(r, (3, 7))
        assert a.accepted and b.accepted
        assert b.mu_c < 1.2  # only textured clutter: A's 100s are not in B's background


@pytest.mark.usefixtures("path")
class TestBlocking:
    def _case(self, blocking):
        x = torch.tensor([[[[10.0, 7.5, 6.5, 6.5, 6.5, 6.5, 7.8, 5.0, 5.0]]]])
        return region_search(
            x, preset="paper", despeckle=None, n_init=1, k=100.0, blocking=blocking
        )

    def test_all_regions_block(self):
        sizes = [r.size for r in self._case("all").tables[0].rows]
        assert sizes == [2, 5]  # 10, 7.5 | 6.5 x4, 7.8 (the 5s are not seeds: 7.8 is near)

    def test_only_targets_block(self):
        rows = self._case("targets").tables[0].rows
        assert [r.size for r in rows] == [2, 9]  # the second region regrows the rejected first


@pytest.mark.usefixtures("path")
class TestMerge:
    def _case(self, merge):
        x = _textured(12, 14)
        x[..., 4:8, 2:5] = 100.0
        x[..., 4:8, 5:8] = 50.0  # touching, but too different to join the first region
        return region_search(x, preset="paper", despeckle=None, guard=1, merge=merge)

    def test_touching_regions(self):
        sep, merged = self._case(None), self._case(0)
        assert torch.equal(sep.detection.mask, merged.detection.mask)
        assert int(sep.detection.labels.max()) == 2 and int(merged.detection.labels.max()) == 1
        assert [r.label for r in merged.tables[0].rows if r.accepted] == [1, 1]


@pytest.mark.usefixtures("path")
class TestSizeLimits:
    def _case(self, **kw):
        x = _textured(12, 12)
        x[..., 4:7, 4:7] = 10.0
        return region_search(x, preset="paper", despeckle=None, guard=1, **kw)

    def test_too_large(self):
        row = _row_of(self._case(max_size=8), (4, 4))
        assert row.reason == "too_large" and row.statistic == -np.inf and row.size == 9

    def test_too_small(self):
        r = self._case(min_size=10)
        row = _row_of(r, (4, 4))
        assert row.reason == "too_small" and not row.accepted
        assert not r.detection.mask.any() and row.statistic > 0.25  # its test statistic stays

    def test_min_size_counts_touching_regions(self):
        x = _textured(12, 14)
        x[..., 4:8, 2:5] = 100.0
        x[..., 4:8, 5:8] = 50.0  # two touching regions of 12 pixels each: one object of 24
        r = region_search(x, preset="paper", despeckle=None, guard=1, min_size=20)
        assert int(r.detection.mask.sum()) == 24

    def test_within_limits(self):
        assert _row_of(self._case(min_size=9, max_size=9), (4, 4)).accepted


@pytest.mark.usefixtures("path")
class TestTargetImage:
    def test_mu_t_on_raw_or_despeckled(self):
        x = _textured(12, 12)
        x[..., 4:7, 4:7] = 10.0
        x[..., 5, 5] = 19.0

        def flat(t):  # a despeckler that flattens the target to its mean
            out = t.clone()
            out[..., 4:7, 4:7] = 11.0
            return out

        raw = _row_of(region_search(x, preset="paper", despeckle=flat), (4, 4))
        den = _row_of(
            region_search(x, preset="paper", despeckle=flat, target_on="despeckled"), (4, 4)
        )
        assert raw.mu_t == pytest.approx(11.0) and den.mu_t == pytest.approx(11.0)
        x[..., 5, 5] = 28.0  # raw mean changes, F does not
        raw2 = _row_of(region_search(x, preset="paper", despeckle=flat), (4, 4))
        assert raw2.mu_t == pytest.approx(12.0)


def test_paper_preset_is_the_paper():
    p = PRESETS["paper"]
    assert (p.tau, p.n_init, p.guard, p.background, p.k, p.min_background) == (
        0.3,
        4,
        3,
        3,
        0.25,
        15,
    )
    assert p.despeckle == "enhanced_frost" and p.connectivity == 4 and p.seed_window == 5
    assert (p.max_size, p.min_size, p.merge) == (None, 1, None)
    assert p == RegionParams()


@pytest.mark.usefixtures("path")
class TestFillHoles:
    def _case(self, fill):
        x = _textured(20, 20)
        x[..., 4:14, 4:14] = 9.0
        x[..., 4:14:2, 4:14] = 11.0  # a target body (rows 11 / 9: one region)
        x[..., 8:10, 8:10] = 16.0  # a bright spot inside: its ring lies on the target itself
        return region_search(
            x, preset="paper", despeckle=None, guard=1, background=1, k=10.0, fill_holes=fill
        )

    def test_enclosed_rejected_region_joins_the_target(self):
        plain, filled = self._case(False), self._case(True)
        spot = _row_of(plain, (8, 8))
        assert not spot.accepted  # background = the target body: z = 6 <= k
        assert not plain.detection.mask[0, 0, 8:10, 8:10].any()
        assert filled.detection.mask[0, 0, 4:14, 4:14].all()
        body = _row_of(filled, (4, 4))
        assert float(filled.detection.statistic[0, 0, 8, 8]) == pytest.approx(body.statistic)
        assert torch.equal(filled.detection.labels > 0, filled.detection.mask)
