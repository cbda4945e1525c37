"""``nn.Module`` wrappers of the speckle filters (for composing pipelines)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

from torch import Tensor, nn

from torchsar.speckle.frost import enhanced_frost, frost
from torchsar.speckle.gamma_map import gamma_map
from torchsar.speckle.lee import enhanced_lee, kuan, lee

__all__ = ["EnhancedFrost", "EnhancedLee", "Frost", "GammaMAP", "Kuan", "Lee"]


class _SpeckleFilter(nn.Module):
    """A speckle filter with fixed options; ``forward(x)`` is one call of the function.

    Keyword options (``window``, ``looks``, ``damping``, ``amplitude``) are those of the
    function and are validated at the first call.
    """

    function: ClassVar[Callable[..., Tensor]]

    def __init__(self, **options: Any) -> None:
        super().__init__()
        self.options = dict(options)

    def forward(self, x: Tensor) -> Tensor:
        """Filter ``x`` ``(B, C, H, W)``."""
        return type(self).function(x, **self.options)

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v!r}" for k, v in self.options.items())


class Lee(_SpeckleFilter):
    """Module form of :func:`~torchsar.speckle.lee`.

    Examples:
        >>> import torch
        >>> Lee(window=3)(torch.ones(1, 1, 5, 5)).shape
        torch.Size([1, 1, 5, 5])
    """

    function = staticmethod(lee)


class Kuan(_SpeckleFilter):
    """Module form of :func:`~torchsar.speckle.kuan`."""

    function = staticmethod(kuan)


class EnhancedLee(_SpeckleFilter):
    """Module form of :func:`~torchsar.speckle.enhanced_lee`."""

    function = staticmethod(enhanced_lee)


class Frost(_SpeckleFilter):
    """Module form of :func:`~torchsar.speckle.frost`."""

    function = staticmethod(frost)


class EnhancedFrost(_SpeckleFilter):
    """Module form of :func:`~torchsar.speckle.enhanced_frost`."""

    function = staticmethod(enhanced_frost)


class GammaMAP(_SpeckleFilter):
    """Module form of :func:`~torchsar.speckle.gamma_map`."""

    function = staticmethod(gamma_map)
