"""Despeckling quality metrics: ENL, ratio-image moments, edge preservation, PSNR, SSIM.

Every metric takes images ``(B, C, H, W)`` and returns one value per image and channel,
``(B, C)``, in the library's float dtype (float64 for float64 input, else float32). Region
metrics take an optional bool ``mask`` broadcastable to the images (``None``: every pixel).
Metrics that compare two images take them in one order, ``(estimate, reference)``: the
despeckled image first, then the clean or noisy image it is judged against.

- :func:`enl` — equivalent number of looks ``mean^2 / var`` of an intensity region
  (no reference image needed).
- :func:`ratio_moments` — mean and variance of the ratio image ``noisy / estimate``; ideal
  filtering of L-look intensity speckle leaves pure speckle: mean 1, variance ``1 / L``.
- :func:`edge_preservation` — Sattar et al.'s EPI: the correlation of the Laplacians of the
  filtered and the clean image (1 = edges kept exactly). Needs the clean image.
- :func:`edge_ratio` — a no-reference edge measure: the summed absolute neighbour differences
  of the filtered image over those of the noisy one (lower = smoother; it falls with any
  smoothing, so read it next to ENL).
- :func:`psnr`, :func:`ssim` — fidelity to the clean reflectivity (SSIM as in Wang et al.
  2004 / scikit-image with Gaussian weights, sigma 1.5, 11x11 window, valid region only).

Constant and zero images (one rule for every metric): when a denominator vanishes, the
value is the ratio's limit where it has one (``inf`` ENL of a constant non-zero region,
``inf`` PSNR of equal images, edge ratio 1 of two images without edges and ``inf`` of an
image with edges over one without); NaN where the quantity has no value (ENL of an all-zero
or empty region, ratio moments with no pixel of ``estimate > 0``, EPI when either Laplacian
is identically zero: a correlation with a constant); and an :class:`InputValueError` when
the caller can fix the cause (PSNR and SSIM of a constant clean image with the default data
range ``max - min = 0``: pass ``data_range``).
"""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar._checks import check_image, check_mask, check_positive, check_same_shape, float_dtype
from torchsar.errors import InputValueError

__all__ = ["edge_preservation", "edge_ratio", "enl", "psnr", "ratio_moments", "ssim"]


def _masked_moments(x: Tensor, mask: Tensor | None) -> tuple[Tensor, Tensor]:
    """Per ``(B, C)`` mean and population variance of ``x`` over ``mask`` (float64;
    NaN where the mask is empty)."""
    x = x.to(torch.float64)
    m = torch.ones_like(x) if mask is None else mask.expand_as(x).to(torch.float64)
    n = m.sum(dim=(-2, -1))
    mean = (x * m).sum(dim=(-2, -1)) / n
    var = ((x - mean[..., None, None]).square() * m).sum(dim=(-2, -1)) / n
    return mean, var


def _pair(a: Tensor, b: Tensor, name_a: str, name_b: str, *, nonnegative: bool = True) -> None:
    check_image(a, name_a, nonnegative=nonnegative)
    check_image(b, name_b, nonnegative=nonnegative)
    check_same_shape(a, b, name_a, name_b)


def _mask(mask: Tensor | None, like: Tensor) -> Tensor | None:
    return None if mask is None else check_mask(mask, like, "mask")


def enl(x: Tensor, *, mask: Tensor | None = None) -> Tensor:
    """Equivalent number of looks ``mean^2 / var`` over a (homogeneous) region.

    Args:
        x: intensity ``(B, C, H, W)``, non-negative.
        mask: bool region, broadcastable to ``x`` (default: the whole image).

    Returns:
        ``(B, C)``; ``inf`` for a constant non-zero region (no speckle left), NaN for an
        all-zero or empty region (no signal to measure).

    Raises:
        InputTypeError, ShapeError, InputValueError: bad input.

    References:
        C. Oliver, S. Quegan, *Understanding Synthetic Aperture Radar Images*, Artech House
        1998 (ENL of intensity images, §4).

    Examples:
        >>> x = torch.tensor([[[[1.0, 3.0], [1.0, 3.0]]]])
        >>> enl(x).item()  # mean 2, variance 1
        4.0
    """
    check_image(x, "x")
    mean, var = _masked_moments(x, _mask(mask, x))
    return (mean.square() / var).to(float_dtype(x.dtype))


def ratio_moments(
    estimate: Tensor, noisy: Tensor, *, mask: Tensor | None = None
) -> tuple[Tensor, Tensor]:
    """Mean and variance of the ratio image ``noisy / estimate`` (intensities).

    Pixels where ``estimate == 0`` are left out (the ratio is undefined there).

    Args:
        estimate: despeckled intensity ``(B, C, H, W)``.
        noisy: the speckled intensity it was computed from, same shape.
        mask: bool region, broadcastable (default: every pixel).

    Returns:
        ``(mean, variance)``, each ``(B, C)``; ideally 1 and ``1 / L``. NaN for an image
        with no pixel where ``estimate > 0`` (an all-zero estimate), inside ``mask``.

    Raises:
        InputTypeError, ShapeError, InputValueError: bad input.

    References:
        Oliver & Quegan, *Understanding Synthetic Aperture Radar Images*, Artech House 1998,
        §6 (ratio image as a filter test).

    Examples:
        >>> x = torch.tensor([[[[1.0, 3.0]]]]); f = torch.tensor([[[[2.0, 2.0]]]])
        >>> [t.item() for t in ratio_moments(f, x)]
        [1.0, 0.25]
    """
    _pair(estimate, noisy, "estimate", "noisy")
    keep = estimate > 0
    m = _mask(mask, noisy)
    keep = keep if m is None else keep & m
    r = noisy.to(torch.float64) / torch.where(keep, estimate.to(torch.float64), 1.0)
    mean, var = _masked_moments(r, keep)
    dtype = float_dtype(noisy.dtype)
    return mean.to(dtype), var.to(dtype)


def _laplacian(x: Tensor) -> Tensor:
    """4-neighbour Laplacian on interior pixels: ``(B, C, H - 2, W - 2)`` float64."""
    x = x.to(torch.float64)
    c = x[..., 1:-1, 1:-1]
    return x[..., :-2, 1:-1] + x[..., 2:, 1:-1] + x[..., 1:-1, :-2] + x[..., 1:-1, 2:] - 4 * c


def edge_preservation(estimate: Tensor, clean: Tensor) -> Tensor:
    """Edge preservation index (Sattar et al. 1997): correlation of the Laplacians.

    ``EPI = sum (dF - mean dF)(dS - mean dS) / sqrt(sum (dF - mean dF)^2 sum (dS - mean dS)^2)``
    with ``dF``, ``dS`` the 4-neighbour Laplacians (kernel ``[[0,1,0],[1,-4,1],[0,1,0]]``) of
    the estimate and the clean image over the interior pixels. 1 means the edges of the clean
    image are kept exactly; compute it on whichever representation (intensity, amplitude)
    the comparison is about.

    Args:
        estimate: despeckled image ``(B, C, H, W)``, H, W >= 3.
        clean: clean reflectivity, same shape.

    Returns:
        ``(B, C)`` in ``[-1, 1]``; NaN when either Laplacian is identically zero (a constant
        or planar image: the correlation with a constant has no value).

    Raises:
        InputTypeError, ShapeError, InputValueError: bad input.

    References:
        F. Sattar, L. Floreby, G. Salomonsson, B. Lovstrom, "Image enhancement based on a
        nonlinear multiscale method", IEEE TIP 6(6), 1997, doi:10.1109/83.585239.

    Examples:
        >>> s = torch.zeros(1, 1, 6, 6); s[..., 3:] = 1.0
        >>> edge_preservation(2 * s + 1, s).item()
        1.0
    """
    _pair(estimate, clean, "estimate", "clean", nonnegative=False)
    if min(clean.shape[-2:]) < 3:
        raise InputValueError(f"images must be at least 3x3, got {tuple(clean.shape[-2:])}")
    df, ds = _laplacian(estimate), _laplacian(clean)
    df = df - df.mean(dim=(-2, -1), keepdim=True)
    ds = ds - ds.mean(dim=(-2, -1), keepdim=True)
    num = (df * ds).sum(dim=(-2, -1))
    den = (df.square().sum(dim=(-2, -1)) * ds.square().sum(dim=(-2, -1))).sqrt()
    return (num / den).to(float_dtype(clean.dtype))


def _total_variation(x: Tensor) -> Tensor:
    """Sum of absolute horizontal and vertical neighbour differences, ``(B, C)`` float64."""
    x = x.to(torch.float64)
    dh = (x[..., :, 1:] - x[..., :, :-1]).abs().sum(dim=(-2, -1))
    dv = (x[..., 1:, :] - x[..., :-1, :]).abs().sum(dim=(-2, -1))
    return dh + dv


def edge_ratio(estimate: Tensor, noisy: Tensor) -> Tensor:
    """No-reference edge measure: ``sum |grad F| / sum |grad I|`` over neighbour pairs.

    Sums of absolute horizontal and vertical neighbour differences of the despeckled image
    divided by those of the noisy image (the gradient-ratio "EPI" of many despeckling
    studies). 1 = as much local contrast as the input; it drops with any smoothing.

    Args:
        estimate: despeckled image ``(B, C, H, W)``.
        noisy: the filter's input, same shape.

    Returns:
        ``(B, C)``; 1 when neither image has any edge (both constant: nothing was smoothed
        away), ``inf`` when only the estimate has edges.

    Raises:
        InputTypeError, ShapeError, InputValueError: bad input.

    Examples:
        >>> x = torch.tensor([[[[0.0, 2.0, 0.0]]]])
        >>> edge_ratio(x / 2, x).item()
        0.5
    """
    _pair(estimate, noisy, "estimate", "noisy", nonnegative=False)
    num, den = _total_variation(estimate), _total_variation(noisy)
    ratio = torch.where(num == den, 1.0, num / den)  # 0 / 0: no edges in either image
    return ratio.to(float_dtype(noisy.dtype))


def _data_range(clean: Tensor, data_range: float | None) -> Tensor:
    """Per-image ``(B, C)`` data range: given, or ``max - min`` of the clean image (which
    must then not be constant)."""
    if data_range is not None:
        v = check_positive(data_range, "data_range")
        return torch.full(clean.shape[:2], v, dtype=torch.float64, device=clean.device)
    flat = clean.to(torch.float64).flatten(-2)
    rng = flat.amax(-1) - flat.amin(-1)
    flat_images = (rng == 0).nonzero().tolist()
    if flat_images:
        b, c = flat_images[0]
        raise InputValueError(
            f"clean image {b} channel {c} is constant, so its data range max - min is 0 and "
            f"the score is undefined; pass data_range (e.g. the sensor's peak value)"
        )
    return rng


def psnr(estimate: Tensor, clean: Tensor, *, data_range: float | None = None) -> Tensor:
    """Peak signal-to-noise ratio ``10 log10(range^2 / MSE)`` in dB, per image and channel.

    Args:
        estimate: restored image ``(B, C, H, W)``.
        clean: clean reference, same shape.
        data_range: peak-to-peak range; default ``max - min`` of each clean image.

    Returns:
        ``(B, C)`` dB (``inf`` when the images are equal).

    Raises:
        InputTypeError, ShapeError, InputValueError, OptionError: bad input.
        InputValueError: a clean image is constant and ``data_range`` is not given.

    Examples:
        >>> c = torch.zeros(1, 1, 2, 2); c[..., 0, 0] = 1.0
        >>> psnr(c + 0.1, c).item()  # MSE 0.01, range 1
        20.0
    """
    _pair(estimate, clean, "estimate", "clean", nonnegative=False)
    rng = _data_range(clean, data_range)
    mse = (estimate.to(torch.float64) - clean.to(torch.float64)).square().mean(dim=(-2, -1))
    return (10 * torch.log10(rng.square() / mse)).to(float_dtype(clean.dtype))


def ssim(estimate: Tensor, clean: Tensor, *, data_range: float | None = None) -> Tensor:
    """Structural similarity (Wang et al. 2004), mean over the valid region, per image.

    Gaussian window (sigma 1.5, 11 x 11), ``K1 = 0.01``, ``K2 = 0.03``, population
    covariances, no padding: equal to ``skimage.metrics.structural_similarity(...,
    gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=...)``.
    Each image is divided by its data range first (SSIM is invariant to that), so ranges may
    differ per image. Computed with :func:`kornia.metrics.ssim`.

    Args:
        estimate: restored image ``(B, C, H, W)``, H, W >= 11.
        clean: clean reference, same shape.
        data_range: dynamic range; default ``max - min`` of each clean image.

    Returns:
        ``(B, C)`` in ``[-1, 1]``.

    Raises:
        InputTypeError, ShapeError, InputValueError, OptionError: bad input.
        InputValueError: a clean image is constant and ``data_range`` is not given.

    References:
        Z. Wang, A. C. Bovik, H. R. Sheikh, E. P. Simoncelli, "Image quality assessment: from
        error visibility to structural similarity", IEEE TIP 13(4), 2004,
        doi:10.1109/TIP.2003.819861.

    Examples:
        >>> c = torch.rand(1, 1, 16, 16, generator=torch.Generator().manual_seed(0))
        >>> round(ssim(c, c).item(), 6)
        1.0
    """
    _pair(estimate, clean, "estimate", "clean", nonnegative=False)
    if min(clean.shape[-2:]) < 11:
        raise InputValueError(f"ssim needs images of at least 11x11, got {tuple(clean.shape)}")
    scale = _data_range(clean, data_range).reciprocal()[..., None, None]
    e = estimate.to(torch.float64) * scale
    c = clean.to(torch.float64) * scale
    import kornia  # here, not at import: torchsar loads without kornia

    smap = kornia.metrics.ssim(e, c, 11, max_val=1.0, eps=0.0, padding="valid")
    return smap.mean(dim=(-2, -1)).to(float_dtype(clean.dtype))
