"""Tests of the region-growing CFAR detector as a whole."""

from __future__ import annotations

import dataclasses
import inspect
import typing

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import torchsar as ts
from tests.reference import region as ref
from torchsar.errors import InputTypeError, OptionError, ShapeError
from torchsar.region import PRESETS, RegionOptions, RegionParams, region_cfar, region_search
from torchsar.region.grow import grow

PAPER = {"preset": "paper", "despeckle": None}


def _speckle_scene(seed: int, size: int = 28) -> torch.Tensor:
    """Gamma speckle (4 looks) with two bright blocks, float64 ``(1, 1, size, size)``."""
    rng = np.random.default_rng(seed)
    clean = np.ones((size, size))
    clean[5:9, 4:10] = 8.0
    clean[16:22, 15:19] = 5.0
    img = clean * rng.gamma(4.0, 0.25, size=clean.shape)
    return torch.from_numpy(img)[None, None]


def _box3(x: torch.Tensor) -> torch.Tensor:
    return ts.windows.box_sums(x, 1, moments=1).mean().to(x.dtype)


@pytest.mark.usefixtures("path")
class TestAgainstReference:
    @settings(max_examples=8)
    @given(
        st.integers(0, 10_000),
        st.sampled_from([4, 8]),
        st.sampled_from(["raw", "despeckled"]),
        st.sampled_from(["all", "targets"]),
    )
    def test_statistic_and_mask(self, seed, conn, target_on, blocking):
        x = _speckle_scene(seed, size=22)
        f = _box3(x)
        opts = dict(connectivity=conn, target_on=target_on, blocking=blocking, budget=8)
        r = region_search(x, preset="paper", despeckle=lambda _: f, **opts)
        stat, rows = ref.region_cfar(
            x[0, 0].numpy(),
            f[0, 0].numpy(),
            connectivity=conn,
            target_on=target_on,
            blocking=blocking,
        )
        np.testing.assert_allclose(r.detection.statistic[0, 0].numpy(), stat, rtol=1e-9)
        assert [t.accepted for t in r.tables[0].rows] == [row["accepted"] for row in rows]
        assert [t.size for t in r.tables[0].rows] == [len(row["region"]) for row in rows]

    def test_lowpass_box(self):
        x = _speckle_scene(3)
        f = _box3(x)
        r = region_cfar(x, preset="paper", despeckle=lambda _: f, lowpass=5)
        low = ts.windows.box_sums(x, 2, moments=1).mean()[0, 0].numpy()
        stat, _ = ref.region_cfar(x[0, 0].numpy(), f[0, 0].numpy(), lowpass=low)
        np.testing.assert_allclose(r.statistic[0, 0].numpy(), stat, rtol=1e-9)


@pytest.mark.usefixtures("path")
class TestContract:
    def test_mask_is_statistic_above_threshold(self):
        d = region_cfar(_speckle_scene(1), despeckle=_box3)
        assert torch.equal(d.mask, d.statistic > d.threshold)
        assert float(d.threshold) == PRESETS["torchsar"].k

    def test_labels_cover_mask(self):
        d = region_cfar(_speckle_scene(2), preset="paper", despeckle=_box3)
        assert torch.equal(d.labels > 0, d.mask)
        assert d.labels.dtype == torch.int64

    def test_table_matches_detection(self):
        r = region_search(_speckle_scene(4), preset="paper", despeckle=_box3)
        tab = r.tables[0]
        acc = [row for row in tab.rows if row.accepted]
        assert sum(row.size for row in acc) == int(r.detection.mask.sum())
        assert sorted({row.label for row in acc}) == list(range(1, len(acc) + 1))
        frame = tab.to_frame()
        assert list(frame.columns[:5]) == ["seed", "size", "mu_t", "mu_c", "sigma_c"]
        assert len(frame) == len(tab)

    @pytest.mark.parametrize("b", [0, 1, 3])
    def test_batch_independence(self, b):
        xs = torch.cat([_speckle_scene(s) for s in range(3)])[:b]
        d = region_cfar(xs, despeckle=_box3)
        assert d.mask.shape == xs.shape
        for i in range(b):
            one = region_cfar(xs[i : i + 1], despeckle=_box3)
            assert torch.equal(one.statistic, d.statistic[i : i + 1])
            assert torch.equal(one.labels, d.labels[i : i + 1])

    def test_workers_give_the_same_result(self):
        xs = torch.cat([_speckle_scene(s) for s in range(3)])
        a = region_cfar(xs, despeckle=_box3)
        b = region_cfar(xs, despeckle=_box3, workers=2)
        assert torch.equal(a.statistic, b.statistic) and torch.equal(a.labels, b.labels)

    def test_channels_are_independent_images(self):
        x = torch.cat([_speckle_scene(5), _speckle_scene(6)], dim=1)
        d = region_cfar(x, despeckle=None)
        assert torch.equal(d.statistic[:, 1:], region_cfar(x[:, 1:], despeckle=None).statistic)

    @pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
    def test_dtype_follows_input(self, dtype):
        d = region_cfar(_speckle_scene(0).to(dtype), despeckle=None)
        assert d.statistic.dtype == dtype and d.threshold.dtype == dtype

    def test_non_contiguous(self):
        x = _speckle_scene(7)
        xt = x.transpose(-1, -2)
        assert not xt.is_contiguous()
        a = region_cfar(xt, despeckle=None)
        b = region_cfar(xt.contiguous(), despeckle=None)
        assert torch.equal(a.statistic, b.statistic)

    @pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
    def test_device_independent(self):
        x = _speckle_scene(9)
        a = region_cfar(x, despeckle=None)
        b = region_cfar(x.cuda(), despeckle=None)
        assert b.statistic.device.type == "cuda"
        assert torch.equal(a.statistic, b.statistic.cpu()) and torch.equal(a.labels, b.labels.cpu())

    def test_deterministic(self):
        x = _speckle_scene(8)
        a, b = region_cfar(x, despeckle=_box3), region_cfar(x, despeckle=_box3)
        assert torch.equal(a.statistic, b.statistic) and torch.equal(a.labels, b.labels)


class TestExceptions:
    def test_not_a_tensor(self):
        with pytest.raises(InputTypeError, match="x must be a torch.Tensor"):
            region_cfar(np.ones((1, 1, 8, 8)))

    def test_shape(self):
        with pytest.raises(ShapeError, match=r"\(B, C, H, W\)"):
            region_cfar(torch.ones(8, 8))

    @pytest.mark.parametrize(
        ("kw", "msg"),
        [
            ({"tau": 0}, "tau must be finite and > 0"),
            ({"n_init": 0}, "n_init must be >= 1"),
            ({"background": 0}, "background must be >= 1"),
            ({"preset": "best"}, "preset must be one of 'paper', 'torchsar'"),
            ({"blocking": "some"}, "blocking must be one of 'all', 'targets'"),
            ({"connectivity": 6}, "connectivity must be 4 or 8"),
            ({"lowpass": 4}, "lowpass must be odd"),
            ({"despeckle": 3}, "despeckle must be a filter name"),
            ({"despeckle": "no_such_filter"}, "not a filter of torchsar.speckle"),
            ({"colour": 1}, "unknown region_cfar option"),
            ({"k": -0.5}, "k must be finite and >= 0"),
            ({"k": float("inf")}, "k must be finite and >= 0"),
            ({"k": float("nan")}, "k must be finite and >= 0"),
            ({"floor": 1.0}, r"floor must be in \[0, 1\)"),
            ({"floor": -0.1}, r"floor must be in \[0, 1\)"),
            ({"floor": True}, r"floor must be in \[0, 1\)"),
        ],
    )
    def test_options(self, kw, msg):
        with pytest.raises(OptionError, match=msg):
            region_cfar(torch.ones(1, 1, 8, 8), **{"despeckle": None, **kw})


def test_max_fraction_rejects_a_flood_covering_most_of_the_image():
    # A bright plateau covering 60 % of the image next to darker clutter: with max_fraction
    # it is a flood (rejected untested), without it the region test may accept it.
    import torch

    import torchsar as ts

    x = torch.ones(1, 1, 40, 40)
    x[..., :, :24] = 20.0
    det = ts.region.region_cfar(x, despeckle=None, max_fraction=0.25, min_size=1)
    assert not det.mask[..., :, :24].any()
    with pytest.raises(ts.errors.OptionError, match="max_fraction"):
        ts.region.region_cfar(x, max_fraction=1.5)


def test_floor_keeps_a_peaked_target_from_flooding_the_image():
    # A 7x7 target at 20 with a sharp peak (100, 50, 30 along a row; the seed is the 100)
    # on clutter near 1: its first four pixels (100, 50, 30, 20) average 50, so at
    # tau = 0.5 the band |F - 50| <= 50 takes every clutter pixel: the region floods the
    # image, is rejected as too large and owns the target. A floor of 0.05 (F >= 5) keeps
    # the region on the target, which is then accepted (the torchsar preset's 0.02 too).
    rng = np.random.default_rng(0)
    x = torch.from_numpy(rng.gamma(20.0, 1 / 20.0, size=(1, 1, 64, 64)))
    x[..., 20:27, 30:37] = 20.0
    x[..., 23, 33:36] = torch.tensor([100.0, 50.0, 30.0], dtype=x.dtype)
    flooded = region_search(x, despeckle=None, floor=0.0)
    assert not flooded.detection.mask.any()
    assert flooded.tables[0].rows[0].reason == "too_large"
    for floor in ({}, {"floor": 0.05}):  # the torchsar preset's 0.02, and 0.05
        kept = region_search(x, despeckle=None, **floor)
        assert kept.detection.mask[0, 0, 20:27, 30:37].all()
        assert int(kept.detection.mask.sum()) == 49
        first = kept.tables[0].rows[0]
        assert first.accepted and first.size == 49


class TestOptionsInTheOpen:
    def test_typed_options_are_exactly_the_parameters(self):
        fields = {f.name for f in dataclasses.fields(RegionParams)}
        assert set(typing.get_type_hints(RegionOptions)) == fields

    def test_one_budget_default(self):
        assert RegionParams().budget == inspect.signature(grow).parameters["budget"].default
        assert PRESETS["paper"].budget == PRESETS["torchsar"].budget == RegionParams().budget

    def test_despeckle_by_name_uses_the_filter_registry(self, monkeypatch):
        x = _speckle_scene(3)
        monkeypatch.setitem(ts.speckle.FILTERS, "box3", _box3)
        by_name = region_cfar(x, despeckle="box3")
        by_callable = region_cfar(x, despeckle=_box3)
        assert torch.equal(by_name.statistic, by_callable.statistic)

    def test_preset_supplies_what_is_not_given(self):
        x = _speckle_scene(5)
        explicit = dataclasses.asdict(PRESETS["paper"]) | {"despeckle": _box3}
        a = region_search(x, preset="paper", despeckle=_box3)
        b = region_search(x, preset="torchsar", **explicit)
        assert a.params == b.params
        assert torch.equal(a.detection.statistic, b.detection.statistic)
