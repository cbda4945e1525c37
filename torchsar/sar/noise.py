"""Receiver noise for simulated phase histories: circular complex white Gaussian, per-item seeds."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import check_choice, check_complex, check_positive
from torchsar.errors import OptionError
from torchsar.sar.geometry import SpotlightGeometry
from torchsar.seeding import check_seed, image_seed, make_generator

__all__ = ["add_noise", "image_noise_std"]


def _noise_std(g: Tensor, snr_db: float | None, std: float | None) -> Tensor:
    """Per-item standard deviation ``(B, 1, 1)`` from exactly one of ``snr_db`` and ``std``."""
    if (snr_db is None) == (std is None):
        raise OptionError(f"give exactly one of snr_db and std, got snr_db={snr_db!r}, std={std!r}")
    if std is not None:
        std = check_positive(std, "std", allow_zero=True)
        return torch.full((g.shape[0], 1, 1), std, dtype=g.real.dtype, device=g.device)
    if isinstance(snr_db, bool) or not isinstance(snr_db, int | float):
        raise OptionError(f"snr_db must be a real number, got {snr_db!r}")
    power = g.abs().square().mean(dim=(-2, -1), keepdim=True)
    return (power / 10 ** (float(snr_db) / 10)).sqrt()


def add_noise(
    g: Tensor, *, snr_db: float | None = None, std: float | None = None, seed: int = 0
) -> Tensor:
    """Add circular complex white Gaussian noise to phase histories ``(B, M, K)``.

    The noise level is either a per-item SNR ``10 log10(mean|g|^2 / sigma^2)`` over
    ``(M, K)`` or a fixed standard deviation ``std`` (``E|n|^2 = std^2``). Item ``b`` draws
    from its own generator seeded with :func:`~torchsar.simulate.image_seed` ``(seed, b)``,
    so an item's noise does not depend on the batch size.

    Args:
        g: complex phase history ``(B, M, K)``.
        snr_db: signal-to-noise ratio of every item in dB.
        std: noise standard deviation per complex sample (give one of ``snr_db``, ``std``).
        seed: random seed, an int in ``[0, 2**63)``.

    Returns:
        Noisy phase history, same shape and dtype.

    Raises:
        InputTypeError, ShapeError: ``g`` is not complex ``(B, M, K)``; OptionError: bad
        ``snr_db``, ``std`` or ``seed``.

    Examples:
        >>> g = torch.ones(2, 8, 8, dtype=torch.complex64)
        >>> add_noise(g, snr_db=20.0, seed=0).shape
        torch.Size([2, 8, 8])
    """
    g = check_complex(g, "g", ndim=3)
    sigma = _noise_std(g, snr_db, std)
    check_seed(seed)
    noise = torch.empty_like(g)
    for b in range(g.shape[0]):
        gen = make_generator(image_seed(seed, b), g.device)
        noise[b] = torch.randn(g.shape[1:], generator=gen, dtype=g.dtype, device=g.device)
    return g + sigma.to(g.real.dtype) * noise


def _taper_gain(n: int, window: str) -> float:
    """``sum w / sqrt(sum w^2)`` of a length-``n`` taper (symmetric Hann or none)."""
    w = torch.ones(n, dtype=torch.float64)
    if window == "hann":
        w = torch.hann_window(n, periodic=False, dtype=torch.float64)
    return float(w.sum() / w.square().sum().sqrt())


def image_noise_std(geometry: SpotlightGeometry, snr_db: float, *, window: str = "hann") -> float:
    """Noise standard deviation per phase-history sample for a given image peak SNR.

    An image formed from the ``M x K`` samples with a separable taper ``w``, normalised so a
    unit-amplitude point scatterer peaks at 1 (as :func:`torchsar.motion.polar_format`
    does), holds noise of variance ``std^2 sum w^2 / (sum w)^2`` per pixel. This returns the
    ``std`` for which a unit point's peak intensity is ``snr_db`` above the mean noise
    intensity: ``std = G_M G_K 10^(-snr_db / 20)``, ``G_n = sum w / sqrt(sum w^2)`` over
    ``n`` samples (``sqrt(2 (n - 1) / 3)`` for Hann). Pass it to :func:`add_noise` as ``std``;
    a point of amplitude ``a`` then has image peak SNR ``snr_db + 20 log10 |a|``.

    Polar formatting resamples range onto a few fewer samples than ``K`` (4 of 180 for the
    Table-1 system), which changes the SNR by less than 0.1 dB.

    Args:
        geometry: the collection (``M = geometry.pulses``, ``K = geometry.samples``).
        snr_db: wanted image peak SNR of a unit-amplitude point in dB.
        window: the image-formation taper, ``"hann"`` or ``"none"``.

    Returns:
        The noise standard deviation per complex sample (``E|n|^2 = std^2``).

    Raises:
        OptionError: ``snr_db`` not a finite number, or an unknown ``window``.

    Examples:
        >>> geo = SpotlightGeometry.for_image((64, 64))
        >>> round(image_noise_std(geo, 20.0, window="none"), 3)  # sqrt(64 * 64) / 10
        6.4
    """
    if isinstance(snr_db, bool) or not isinstance(snr_db, int | float) or not math.isfinite(snr_db):
        raise OptionError(f"snr_db must be a finite real number, got {snr_db!r}")
    check_choice(window, "window", ("hann", "none"))
    gain = _taper_gain(geometry.pulses, window) * _taper_gain(geometry.samples, window)
    return gain * 10 ** (-float(snr_db) / 20)
