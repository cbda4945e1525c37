"""Receiver noise for simulated phase histories: circular complex white Gaussian, per-item seeds."""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar._checks import OptionError, check_complex, check_positive
from torchsar.simulate.seeding import check_seed, image_seed, make_generator

__all__ = ["add_noise"]


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

    Example:
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
