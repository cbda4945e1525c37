"""Speckle filters by name (for command lines and pipeline configurations)."""

from __future__ import annotations

from collections.abc import Callable

from torch import Tensor

from torchsar.speckle.frost import enhanced_frost, frost
from torchsar.speckle.gamma_map import gamma_map
from torchsar.speckle.lee import enhanced_lee, kuan, lee

__all__ = ["FILTERS"]

#: Every filter takes ``(x, *, window, looks, amplitude)``; ``enhanced_lee``, ``frost`` and
#: ``enhanced_frost`` also take ``damping``.
FILTERS: dict[str, Callable[..., Tensor]] = {
    "lee": lee,
    "kuan": kuan,
    "enhanced_lee": enhanced_lee,
    "frost": frost,
    "enhanced_frost": enhanced_frost,
    "gamma_map": gamma_map,
}
