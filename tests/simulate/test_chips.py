"""Simulated chips: determinism, batch independence, ground-truth consistency, errors."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchsar.errors import OptionError
from torchsar.simulate import SimBatch, chips, image_seed

from .groundtruth import assert_ground_truth


@pytest.fixture(scope="module")
def batch() -> SimBatch:
    return chips(6, size=96, length_px=(16, 48), seed=4)


def _equal(a: SimBatch, i: int, b: SimBatch, j: int) -> bool:
    x, y = a[i], b[j]
    same = all(torch.equal(x[k], y[k]) for k in ("image", "clean", "mask", "instances", "ignore"))
    return same and x["meta"]["boxes"] == y["meta"]["boxes"]


def test_shapes_dtypes(batch):
    assert len(batch) == 6
    for name, dtype in [
        ("image", torch.float32),
        ("clean", torch.float32),
        ("mask", torch.bool),
        ("instances", torch.int32),
        ("ignore", torch.bool),
    ]:
        t = getattr(batch, name)
        assert t.shape == (6, 1, 96, 96) and t.dtype == dtype
    item = batch[2]
    assert item["image"].shape == (1, 96, 96)
    assert item["meta"]["classes"] == ["vehicle"] and item["meta"]["pixel_m"] == 0.3


def test_empty():
    b = chips(0)
    assert len(b) == 0 and b.image.shape == (0, 1, 128, 128) and b.mask.dtype == torch.bool


def test_deterministic():
    a = chips(3, size=64, length_px=(16, 30), model="k", seed=9)
    b = chips(3, size=64, length_px=(16, 30), model="k", seed=9)
    c = chips(3, size=64, length_px=(16, 30), model="k", seed=10)
    assert all(torch.equal(getattr(a, k), getattr(b, k)) for k in ("image", "clean", "instances"))
    assert not torch.equal(a.image, c.image)


def test_batch_size_independent(batch):
    for i in (0, 3, 5):
        alone = chips(1, size=96, length_px=(16, 48), seed=image_seed(4, i))
        assert _equal(batch, i, alone, 0)
        shifted = chips(2, size=96, length_px=(16, 48), seed=4, start=i)
        assert _equal(batch, i, shifted, 0)
    assert _equal(batch, 1, chips(2, size=96, length_px=(16, 48), seed=4), 1)


def test_ground_truth(batch):
    assert_ground_truth(batch, (15.0, 35.0))
    assert int(batch.instances.max()) == 1
    background = batch.clean[~batch.mask & ~batch.ignore]
    assert torch.equal(background, torch.ones_like(background))  # clutter mean 1 = reference
    assert all(m["targets"][0]["clutter_mean"] == 1.0 for m in batch.meta)
    assert batch.ignore.any(dim=(1, 2, 3)).all()  # every chip has a shadow


def test_shadow_is_dark_and_behind(batch):
    for i in range(len(batch)):
        ign, clean, mask = batch.ignore[i, 0], batch.clean[i, 0], batch.mask[i, 0]
        assert float(clean[ign].max()) <= 0.1 + 1e-6
        rows_t = torch.nonzero(mask)[:, 0].float().mean()
        rows_s = torch.nonzero(ign)[:, 0].float().mean()
        assert rows_s > rows_t  # far range = increasing rows


def test_target_size_in_range(batch):
    for m in batch.meta:
        t = m["targets"][0]
        assert 16 <= t["length_px"] <= 48 and 0.4 <= t["width_px"] / t["length_px"] <= 0.55


def test_clutter_background_statistics():
    b = chips(40, size=128, model="gamma", looks=4.0, seed=2)
    bg = b.image[(~b.mask) & (~b.ignore)]
    assert float(bg.mean()) == pytest.approx(1.0, abs=0.01)  # ~6e5 px, s.e. 6e-4
    assert float(bg.mean() ** 2 / bg.var()) == pytest.approx(4.0, rel=0.03)


@pytest.mark.parametrize("model", ["exponential", "k", "g0", "lognormal", "weibull"])
def test_models_run(model):
    looks = 1.0
    b = chips(2, size=80, length_px=(16, 32), model=model, looks=looks)
    assert b.meta[0]["clutter"]["model"] == model
    assert torch.isfinite(b.image).all() and (b.image >= 0).all()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n": -1}, "n must be >= 0"),
        ({"n": 2.0}, "n must be an int"),
        ({"size": 40}, "size must be >= "),
        ({"model": "rice"}, "'gamma'"),
        ({"target_db": (30, 10)}, "target_db"),
        ({"length_px": (2, 10)}, "length_px"),
        ({"seed": 2**63}, "seed"),
        ({"looks": -1.0}, "looks"),
        ({"model": "weibull", "shape_param": 0.01}, "shape_param must be >= 0.18"),
        ({"model": "lognormal", "shape_param": 12.0}, "shape_param must be > 0 and <= 9"),
        ({"model": "k", "looks": 0.1}, "looks must be >= 0.16"),
        ({"device": "nodevice"}, "device must be a torch.device"),
    ],
)
def test_errors(kwargs, match):
    kwargs = {"n": 1, **kwargs}
    n = kwargs.pop("n")
    with pytest.raises(OptionError, match=match):
        chips(n, **kwargs)


@settings(max_examples=10, deadline=None)
@given(
    seed=st.integers(0, 2**63 - 1),
    size=st.integers(48, 80),
    low=st.floats(8.0, 30.0),
    db=st.tuples(st.floats(3.0, 20.0), st.floats(0.0, 20.0)),
)
def test_ground_truth_property(seed, size, low, db):
    """Any seed, chip size and level range gives consistent ground truth inside the chip."""
    target_db = (db[0], db[0] + db[1])
    length = (low, min(low * 1.5, (size - 6) / 1.15))
    if length[1] < length[0]:
        with pytest.raises(OptionError, match="size must be"):
            chips(1, size=size, length_px=(low, low * 1.5), seed=seed)
        return
    b = chips(2, size=size, length_px=length, seed=seed, target_db=target_db)
    assert_ground_truth(b, target_db)
    assert b.ignore.any()
