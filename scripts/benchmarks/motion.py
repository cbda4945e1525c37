"""Benchmark cases for torchsar.motion against scipy / scikit-image references.

- batched sub-pixel registration vs a loop of skimage.registration.phase_cross_correlation;
- chirp-z transform with one frequency step per row vs a loop of scipy.signal.czt;
- the circular window maximum of the peak suppression vs scipy.ndimage.maximum_filter.

Run: ``python scripts/benchmark.py --topic motion`` (1 thread).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from scipy import ndimage, signal
from skimage.registration import phase_cross_correlation

from torchsar.motion import czt, estimate_shift
from torchsar.motion.peaks import window_max


def _registration_case():
    gen = torch.Generator().manual_seed(0)
    ref = torch.rand(64, 32, 32, generator=gen, dtype=torch.float64)
    mov = torch.roll(ref, (2, -1), dims=(-2, -1)) + 0.05 * torch.rand(64, 32, 32, generator=gen)
    a, b = ref.numpy(), mov.numpy()

    def reference():
        return [
            phase_cross_correlation(a[i], b[i], upsample_factor=20, normalization=None)[0]
            for i in range(64)
        ]

    return (
        "estimate_shift 64 chips 32x32 up=20 vs skimage phase_cross_correlation loop",
        lambda: estimate_shift(ref, mov, upsample=20),
        reference,
    )


def _czt_case():
    gen = torch.Generator().manual_seed(1)
    x = torch.randn(175, 500, dtype=torch.complex128, generator=gen)
    alpha = torch.linspace(0.005, 0.006, 175, dtype=torch.float64)
    xn, an = x.numpy(), alpha.numpy()

    def reference():
        return [signal.czt(xn[i], 1024, np.exp(1j * an[i]), 1.0) for i in range(175)]

    return (
        "czt 175 rows x 500 -> 1024, per-row step vs scipy.signal.czt loop",
        lambda: czt(x, alpha, 1024),
        reference,
    )


def _window_max_case():
    gen = torch.Generator().manual_seed(2)
    x = torch.rand(1, 1, 1024, 1024, generator=gen)
    a = x[0, 0].numpy()
    return (
        "peak window max 1024x1024 r=12 (circular) vs scipy.ndimage.maximum_filter",
        lambda: window_max(x, 12),
        lambda: ndimage.maximum_filter(a, size=25, mode="wrap"),
    )


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    return [_registration_case(), _czt_case(), _window_max_case()]
