"""Per-image seeds and generators: what makes simulated batches independent of batch size.

Every simulated image draws all its random numbers (geometry, levels, clutter) from its own
:class:`torch.Generator`, seeded with :func:`image_seed` ``(seed, index)``. Image ``i`` of a
batch therefore never depends on the batch size or on the other images, and
``chips(1, seed=image_seed(s, i))`` reproduces image ``i`` of ``chips(n, seed=s)`` exactly
(``image_seed(s, 0) == s``), as does ``chips(1, seed=s, start=i)``.
"""

from __future__ import annotations

import torch

from torchsar import _checks as checks
from torchsar._checks import check_int
from torchsar.errors import OptionError

__all__ = ["Draws", "check_device", "check_seed", "image_seed", "make_generator"]

_MASK64 = (1 << 64) - 1
_MAX_SEED = (1 << 63) - 1


def _splitmix64(z: int) -> int:
    """The splitmix64 finaliser (Steele et al. 2014): a bijective 64-bit bit mixer."""
    z = (z + 0x9E3779B97F4A7C15) & _MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


def image_seed(seed: int, index: int) -> int:
    """Return the seed of image ``index`` in a batch generated with ``seed``.

    ``image_seed(seed, 0) == seed``; for ``index > 0`` the result is a splitmix64 mix of
    ``(seed, index)`` in ``[0, 2**63)``. Pure Python, identical on every platform.

    Args:
        seed: the batch seed, an int in ``[0, 2**63)``.
        index: the image index, an int >= 0.

    Returns:
        The per-image seed, an int in ``[0, 2**63)``.

    Raises:
        OptionError: ``seed`` or ``index`` is not a non-negative int (or seed >= 2**63).

    Examples:
        >>> image_seed(7, 0)
        7
        >>> image_seed(7, 1) == image_seed(7, 1) != image_seed(7, 2)
        True
    """
    check_seed(seed)
    check_int(index, "index", minimum=0)
    if index == 0:
        return seed
    return _splitmix64(_splitmix64(seed) ^ index) & _MAX_SEED


def check_seed(seed: object, name: str = "seed") -> int:
    """Validate a seed: an int in ``[0, 2**63)``."""
    value = check_int(seed, name, minimum=0)
    if value > _MAX_SEED:
        raise OptionError(f"{name} must be < 2**63, got {value}")
    return value


def check_device(device: object) -> torch.device:
    """Validate a device (``None``: CPU) with :func:`torchsar._checks.check_device` and check
    that random numbers can be drawn on it.

    Raises:
        OptionError: not a device, or a device this machine or torch build does not have
            (e.g. ``"cuda"`` without a GPU).
    """
    dev = checks.check_device(device) or torch.device("cpu")
    try:
        torch.Generator(device=dev)
    except RuntimeError as exc:
        reason = str(exc).split(".")[0]
        raise OptionError(
            f"device = {device!r} is not available here ({reason}); use device='cpu'"
        ) from None
    return dev


def make_generator(seed: int, device: torch.device | str | None = None) -> torch.Generator:
    """Return a :class:`torch.Generator` on ``device`` (CPU by default) seeded with ``seed``."""
    return torch.Generator(device=torch.device(device or "cpu")).manual_seed(seed)


class Draws:
    """Scalar random draws (Python numbers) from one generator, for per-target geometry.

    Uniforms are drawn from ``generator`` in blocks of ``block`` (float64) and handed out in
    order, so scalar draws cost one generator call per block; the sequence is deterministic
    for a given seed, and tensor draws made directly from ``generator`` (clutter, facets)
    interleave deterministically with the block refills.

    Args:
        generator: the per-image generator; every draw advances it.
        block: number of uniforms fetched per refill.
    """

    def __init__(self, generator: torch.Generator, block: int = 64) -> None:
        self.generator = generator
        self._block = block
        self._buffer: list[float] = []

    def _next(self, n: int) -> list[float]:
        """The next ``n`` uniforms in ``[0, 1)``."""
        while len(self._buffer) < n:
            u = torch.rand(
                self._block,
                generator=self.generator,
                dtype=torch.float64,
                device=self.generator.device,
            )
            self._buffer.extend(u.cpu().tolist())
        out, self._buffer = self._buffer[:n], self._buffer[n:]
        return out

    def uniform(self, low: float, high: float, n: int | None = None) -> float | list[float]:
        """One float (or a list of ``n``) uniform in ``[low, high)``."""
        values = [low + (high - low) * u for u in self._next(1 if n is None else n)]
        return values[0] if n is None else values

    def integer(self, low: int, high: int) -> int:
        """One int uniform in ``[low, high]`` (both ends included)."""
        return min(high, low + int(self._next(1)[0] * (high - low + 1)))
