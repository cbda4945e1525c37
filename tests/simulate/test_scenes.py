"""Simulated scenes: determinism, batch independence, ground truth, target kinds, errors."""

from __future__ import annotations

import pytest
import torch

from torchsar.errors import OptionError
from torchsar.simulate import SimBatch, image_seed, scenes

from .groundtruth import assert_ground_truth

KW = {"size": 256, "building_px": (30, 60), "vehicle_px": (10, 24), "n_targets": (5, 15)}


@pytest.fixture(scope="module")
def batch() -> SimBatch:
    return scenes(3, seed=7, **KW)


def test_shapes_and_counts(batch):
    assert batch.image.shape == (3, 1, 256, 256) and batch.instances.dtype == torch.int32
    for m in batch.meta:
        assert 5 <= len(m["boxes"]) <= 15
        assert "building" in m["classes"] and "vehicle" in m["classes"]
        assert m["region_map"].shape == (256, 256)


def test_ground_truth(batch):
    assert_ground_truth(batch, (15.0, 35.0))


def test_clutter_mean_reference_is_local(batch):
    """Each target's reference mean is the region mean at its centre pixel."""
    for i, m in enumerate(batch.meta):
        table = [c["mean_db"] for c in m["regions"]["cells"]]
        if m["regions"]["road"] is not None:
            table.append(m["regions"]["road"]["mean_db"])
        for t in m["targets"]:
            r, c = (min(max(round(v), 0), 255) for v in t["center_rc"])
            expected = 10 ** (table[int(m["region_map"][r, c])] / 10)
            assert t["clutter_mean"] == pytest.approx(expected, rel=1e-5)
        background = ~batch.mask[i, 0] & ~batch.ignore[i, 0]
        means = torch.tensor([10 ** (v / 10) for v in table])[m["region_map"].long()]
        assert torch.allclose(batch.clean[i, 0][background], means[background], rtol=1e-5)


def test_regions_differ_within_10db(batch):
    for m in batch.meta:
        dbs = [c["mean_db"] for c in m["regions"]["cells"]] + [m["regions"]["road"]["mean_db"]]
        assert max(dbs) - min(dbs) <= 10.0


def _gap(a: torch.Tensor, b: torch.Tensor) -> float:
    """Smallest Euclidean distance between the pixels of two masks."""
    pa, pb = torch.nonzero(a).float(), torch.nonzero(b).float()
    return float(torch.cdist(pa, pb).min())


def test_groups_are_tight(batch):
    seen = 0
    for i, m in enumerate(batch.meta):
        inst = batch.instances[i, 0]
        for g in {t["group"] for t in m["targets"] if t["group"] >= 0}:
            ids = [j + 1 for j, t in enumerate(m["targets"]) if t["group"] == g]
            assert len(ids) >= 2
            for a in ids:  # each member has a neighbour 2-6 px (+ raster rounding) away
                gaps = [_gap(inst == a, inst == b) for b in ids if b != a]
                assert 2.0 <= min(gaps) <= 7.5
            seen += 1
    assert seen >= 1


def test_near_edge_targets(batch):
    seen = 0
    for m in batch.meta:
        labels = m["region_map"]
        for t in m["targets"]:
            if not t["near_edge"]:
                continue
            r, c = (round(v) for v in t["center_rc"])
            win = labels[max(0, r - 12) : r + 13, max(0, c - 12) : c + 13]
            assert len(torch.unique(win)) >= 2  # a region boundary within 12 px
            seen += 1
    assert seen >= 1


def test_deterministic_and_batch_independent(batch):
    again = scenes(1, seed=image_seed(7, 2), **KW)
    assert torch.equal(again.image[0], batch.image[2])
    assert torch.equal(again.instances[0], batch.instances[2])
    assert scenes(1, seed=7, start=1, **KW)[0]["meta"]["boxes"] == batch.meta[1]["boxes"]


def test_options():
    b = scenes(1, size=256, n_targets=(6, 6), large=False, groups=False, road=False, seed=1)
    assert b.meta[0]["classes"] == ["vehicle"] * len(b.meta[0]["classes"])
    assert b.meta[0]["regions"]["road"] is None
    assert len(b.meta[0]["boxes"]) == 6
    e = scenes(0, size=200, building_px=(30, 60))
    assert e.image.shape == (0, 1, 200, 200)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n": -2}, "n must be >= 0"),
        ({"size": 64}, "size must be >= "),
        ({"n_targets": (5, 2)}, "n_targets"),
        ({"regions": (0, 2)}, "regions"),
        ({"road": 1}, "road must be True or False"),
        ({"model": "foo"}, "'weibull'"),
    ],
)
def test_errors(kwargs, match):
    kwargs = {"n": 1, **kwargs}
    n = kwargs.pop("n")
    with pytest.raises(OptionError, match=match):
        scenes(n, **kwargs)
