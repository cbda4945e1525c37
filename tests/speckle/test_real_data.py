"""Speckle filters on real MSTAR chips (skipped when the real-data folder is absent)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from skimage import io

from tests.speckle._cases import NAMES, call
from torchsar.metrics.despeckling import enl


@pytest.mark.parametrize("name", NAMES)
def test_mstar_chip(data_dir, name):
    stem = sorted((data_dir / "mstar_sarbake" / "T72").glob("*.mask.png"))[0]
    chip = stem.with_name(stem.name.replace(".mask.png", ".jpeg"))
    amp = io.imread(chip).astype(np.float64) / 255.0
    clutter = torch.from_numpy(io.imread(stem) == 0)[None, None]
    x = torch.from_numpy(amp**2)[None, None].float()
    out = call(name, x, window=7)
    assert bool(torch.isfinite(out).all()) and bool((out >= 0).all())
    assert out.shape == x.shape and out.dtype == torch.float32
    assert enl(out, mask=clutter).item() > 1.5 * enl(x, mask=clutter).item()
