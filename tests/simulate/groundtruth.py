"""Shared ground-truth consistency checks for simulated batches."""

from __future__ import annotations

import torch
from torch import Tensor
from torch.nn import functional as nnf

from torchsar.simulate import SimBatch


def assert_separated(instances: Tensor) -> None:
    """No two instances touch (not even diagonally): each 3x3 neighbourhood of a target pixel
    holds only its own id and background."""
    x = instances.float()
    high = nnf.max_pool2d(x, 3, stride=1, padding=1)
    low = -nnf.max_pool2d(torch.where(x > 0, -x, -1e9), 3, stride=1, padding=1)
    on = instances > 0
    assert torch.equal(high[on], x[on]) and torch.equal(low[on], x[on])


def assert_ground_truth(batch: SimBatch, target_db: tuple[float, float]) -> None:
    """Check mask/instances/ignore/boxes/contrast consistency of every image in ``batch``."""
    assert torch.equal(batch.mask, batch.instances > 0)
    assert not (batch.ignore & batch.mask).any()
    assert (batch.clean >= 0).all() and (batch.image >= 0).all()
    assert_separated(batch.instances)
    for i, meta in enumerate(batch.meta):
        inst, clean = batch.instances[i, 0], batch.clean[i, 0]
        k = int(inst.max())
        assert len(meta["boxes"]) == len(meta["classes"]) == k
        assert set(torch.unique(inst).tolist()) == set(range(k + 1))  # ids 1..k, no gaps
        for ident, (r0, c0, r1, c1) in enumerate(meta["boxes"], start=1):
            pixels = inst == ident
            inside = torch.zeros_like(pixels)
            inside[r0:r1, c0:c1] = True
            assert pixels.any() and not (pixels & ~inside).any()
            rows, cols = torch.nonzero(pixels, as_tuple=True)  # box is tight
            assert (int(rows.min()), int(cols.min()), int(rows.max()) + 1, int(cols.max()) + 1) == (
                r0,
                c0,
                r1,
                c1,
            )
            ref = meta["targets"][ident - 1]["clutter_mean"]
            db = 10 * torch.log10(clean[pixels] / ref)
            assert float(db.min()) >= target_db[0] - 1e-3 and float(db.max()) <= target_db[1] + 1e-3
