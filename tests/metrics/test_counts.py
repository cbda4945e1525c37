from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.reference.metrics import object_scores
from torchsar.errors import InputTypeError, ShapeError
from torchsar.metrics import ObjectCounts, PixelCounts, object_counts, pixel_counts


def _t(a, dtype=torch.bool):
    return torch.as_tensor(np.asarray(a)).to(dtype)[None, None]


class TestPixelCounts:
    def test_hand_made(self):
        pred = _t([[1, 1, 0], [0, 1, 0], [0, 0, 1]])
        tgt = _t([[1, 1, 1], [0, 0, 0], [0, 0, 0]])
        ign = _t([[0, 0, 0], [0, 0, 0], [0, 0, 1]])
        c = pixel_counts(pred, tgt, ignore=ign)
        assert c == PixelCounts(tp=2, fp=1, targets=3, clutter=5)
        assert c.pd == pytest.approx(2 / 3)
        assert c.pfa == pytest.approx(1 / 5)

    @given(seed=st.integers(0, 10_000), with_ignore=st.sampled_from([None, "some", "none"]))
    def test_equals_counting_by_definition(self, seed, with_ignore):
        rng = np.random.default_rng(seed)
        pred, tgt = rng.random((2, 3, 1, 6, 7)) < 0.3
        ign = (
            None
            if with_ignore is None
            else rng.random((3, 1, 6, 7)) < (0.2 if with_ignore == "some" else 0)
        )
        care = np.ones_like(pred) if ign is None else ~ign
        got = pixel_counts(
            torch.as_tensor(pred),
            torch.as_tensor(tgt),
            ignore=None if ign is None else torch.as_tensor(ign),
        )
        want = PixelCounts(
            tp=int((pred & tgt & care).sum()),
            fp=int((pred & ~tgt & care).sum()),
            targets=int((tgt & care).sum()),
            clutter=int((~tgt & care).sum()),
        )
        assert got == want

    def test_additive(self):
        a, b = PixelCounts(1, 2, 3, 4), PixelCounts(10, 20, 30, 40)
        assert a + b == PixelCounts(11, 22, 33, 44)

    def test_errors(self):
        with pytest.raises(InputTypeError, match="pred must be a bool tensor"):
            pixel_counts(torch.zeros(2, 2), torch.zeros(2, 2, dtype=torch.bool))
        with pytest.raises(ShapeError):
            pixel_counts(torch.zeros(2, 2, dtype=torch.bool), torch.zeros(3, 2, dtype=torch.bool))


class TestObjectCounts:
    def test_hand_made(self):
        inst = np.zeros((10, 10), int)
        inst[1:4, 1:4] = 1  # detected in two fragments
        inst[6:9, 6:9] = 2  # missed
        inst[1:3, 7:9] = 3  # detected exactly
        pred = np.zeros((10, 10), bool)
        pred[1, 1] = pred[3, 3] = True  # two fragments of instance 1 (not 8-adjacent)
        pred[1:3, 7:9] = True
        pred[8, 1] = True  # a false alarm
        pred[5, 5] = True  # inside ignore: not a false alarm
        ignore = np.zeros((10, 10), bool)
        ignore[5, 5] = True
        c = object_counts(_t(pred), _t(inst, torch.int32), ignore=_t(ignore))
        assert (c.instances, c.detected, c.false_alarms, c.fragments) == (3, 2, 1, 3)
        assert c.fragmentation == 1.5
        assert c.iou_sum == pytest.approx(2 / 9 + 1.0)
        assert c.fom == pytest.approx(2 / (1 + 3))
        assert c.pd == pytest.approx(2 / 3)

    @given(seed=st.integers(0, 10_000), density=st.floats(0.05, 0.6))
    def test_matches_reference(self, seed, density):
        rng = np.random.default_rng(seed)
        inst = np.zeros((24, 24), int)
        for k in range(1, 5):
            r, c = rng.integers(0, 20, 2)
            inst[r : r + rng.integers(1, 5), c : c + rng.integers(1, 5)] = k
        pred = rng.random((24, 24)) < density
        ignore = (rng.random((24, 24)) < 0.1) & (inst == 0)
        got = object_counts(_t(pred), _t(inst, torch.int32), ignore=_t(ignore))
        ref = object_scores(pred, inst, ignore)
        for key in ("instances", "detected", "false_alarms", "fragments"):
            assert getattr(got, key) == ref[key], key
        assert got.iou_sum == pytest.approx(ref["iou_sum"])

    def test_batch_sums_images(self):
        inst = torch.zeros(2, 1, 5, 5, dtype=torch.int32)
        inst[:, :, 1:3, 1:3] = 1
        pred = inst > 0
        c = object_counts(pred, inst)
        assert c == ObjectCounts(
            images=2, instances=2, detected=2, false_alarms=0, fragments=2, iou_sum=2.0
        )

    def test_empty_is_nan_not_error(self):
        c = object_counts(
            torch.zeros(0, 1, 4, 4, dtype=torch.bool), torch.zeros(0, 1, 4, 4, dtype=torch.int32)
        )
        assert c.images == 0 and np.isnan(c.pd)


def test_object_counts_connectivity_is_validated():
    from torchsar.errors import OptionError

    z = torch.zeros(1, 1, 4, 4, dtype=torch.bool)
    with pytest.raises(OptionError, match="connectivity"):
        object_counts(z, torch.zeros(1, 1, 4, 4, dtype=torch.int32), connectivity=3)
