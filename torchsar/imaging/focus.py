"""Focus metrics of formed SAR images: how sharp an image is, with no reference needed.

Each takes real intensity images ``(B, C, H, W)`` of any magnitude (the metrics do not
depend on the scale) and returns ``(B, C)``: :func:`entropy`
(lower is better focused), :func:`contrast` and :func:`sharpness` (higher is better), and
:func:`target_to_background` given a target mask. The minimum-entropy autofocus methods
minimise :func:`intensity_entropy`, the same entropy without the input checks.

Fidelity to a known scene or phase error is in :mod:`torchsar.imaging.fidelity`; detection
scoring and despeckling quality (ENL, PSNR, SSIM, ...) are in :mod:`torchsar.metrics`.
"""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar._checks import check_image, check_same_shape, float_dtype
from torchsar._scale import unit_scale

__all__ = [
    "contrast",
    "entropy",
    "entropy_terms",
    "intensity_entropy",
    "sharpness",
    "target_to_background",
]


def _intensity(x: Tensor) -> Tensor:
    """Flattened intensity ``(B, C, H W)`` in the policy dtype, each plane divided by a
    power of two (exact) near its peak: every metric here is a ratio that does not depend on
    the scale, and huge intensities would otherwise overflow their squares and sums."""
    x = check_image(x, "x")
    i = x.flatten(-2).to(float_dtype(x.dtype))
    return i / unit_scale(i, dims=1)


def entropy(x: Tensor) -> Tensor:
    """Shannon entropy of the normalised intensity ``-sum q log q``, ``q = I / sum I``.

    Lower is better focused. A constant image gives ``log(H W)``; an all-zero image gives 0.

    Args:
        x: intensity ``(B, C, H, W)``.

    Returns:
        ``(B, C)``.

    References:
        Xi, Guosui & Ni, IEEE Trans. AES 35(4), 1999, doi:10.1109/7.805442.

    Examples:
        >>> round(float(entropy(torch.ones(1, 1, 4, 4))[0, 0]), 4) == round(4 * 0.693147, 4)
        True
    """
    return intensity_entropy(_intensity(x))


def intensity_entropy(i: Tensor) -> Tensor:
    """Entropy ``-sum q log q`` of ``q = i / sum i`` along the last dim (no input checks).

    The objective of the minimum-entropy autofocus methods (differentiable; an all-zero
    row gives 0).

    Args:
        i: non-negative intensities ``(..., N)``.

    Returns:
        ``(...)``.

    Examples:
        >>> round(float(intensity_entropy(torch.ones(4))), 4) == round(2 * 0.693147, 4)
        True
    """
    return entropy_terms(i).sum(-1)


def entropy_terms(i: Tensor) -> Tensor:
    """The terms ``-q log q`` of :func:`intensity_entropy`, ``q = i / sum i`` along the last dim.

    Examples:
        >>> [round(v, 4) for v in entropy_terms(torch.tensor([1.0, 1.0, 0.0])).tolist()]
        [0.3466, 0.3466, 0.0]
    """
    tiny = torch.finfo(i.dtype).tiny
    q = i / i.sum(-1, keepdim=True).clamp_min(tiny)
    return -(q * q.clamp_min(tiny).log())


def contrast(x: Tensor) -> Tensor:
    """Image contrast ``std(I) / mean(I)`` (higher is better focused).

    Examples:
        >>> float(contrast(torch.ones(1, 1, 4, 4))[0, 0])
        0.0
    """
    i = _intensity(x)
    return i.std(-1, unbiased=False) / i.mean(-1).clamp_min(torch.finfo(i.dtype).tiny)


def sharpness(x: Tensor) -> Tensor:
    """Normalised sharpness ``sum I^2 / (sum I)^2`` (Fienup & Miller 2003; higher is sharper).

    Equals 1 for a single bright pixel and ``1 / (H W)`` for a constant image.

    References:
        Fienup & Miller, JOSA A 20(4), 2003, doi:10.1364/JOSAA.20.000609.

    Examples:
        >>> float(sharpness(torch.ones(1, 1, 2, 2))[0, 0])
        0.25
    """
    i = _intensity(x)
    return i.square().sum(-1) / i.sum(-1).square().clamp_min(torch.finfo(i.dtype).tiny)


def target_to_background(x: Tensor, mask: Tensor) -> Tensor:
    """Target-to-background ratio in dB: mean intensity on ``mask`` over mean off it.

    Args:
        x: intensity ``(B, C, H, W)``.
        mask: bool target mask, same shape.

    Returns:
        ``(B, C)`` in dB.

    Examples:
        >>> x = torch.ones(1, 1, 2, 2); x[0, 0, 0, 0] = 10
        >>> m = torch.zeros(1, 1, 2, 2, dtype=torch.bool); m[0, 0, 0, 0] = True
        >>> float(target_to_background(x, m)[0, 0])
        10.0
    """
    i = _intensity(x)
    check_same_shape(x, mask, "x", "mask")
    m = mask.flatten(-2).to(i.dtype)
    tiny = torch.finfo(i.dtype).tiny
    tgt = (i * m).sum(-1) / m.sum(-1).clamp_min(1)
    bkg = (i * (1 - m)).sum(-1) / (1 - m).sum(-1).clamp_min(1)
    return 10 * torch.log10(tgt.clamp_min(tiny) / bkg.clamp_min(tiny))
