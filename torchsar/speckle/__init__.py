"""Speckle filters: Lee, Kuan, enhanced Lee, Frost, enhanced Frost, Gamma-MAP.

All take intensity ``(B, C, H, W)`` (amplitude with ``amplitude=True``), an odd ``window``
and the number of ``looks``; window statistics over in-image cells, interior pixels exact.
:data:`FILTERS` maps names to the functions (for command lines and pipelines). The filters
support autograd: they are differentiable almost everywhere (not on the class boundaries
``Ci = Cu``, ``Ci = Cmax``), window sums are updated in place only when no gradient is
recorded, and a constant or zero window gets a finite gradient.
"""

from torchsar.speckle.frost import enhanced_frost, frost
from torchsar.speckle.gamma_map import gamma_map
from torchsar.speckle.lee import enhanced_lee, kuan, lee
from torchsar.speckle.modules import EnhancedFrost, EnhancedLee, Frost, GammaMAP, Kuan, Lee
from torchsar.speckle.registry import FILTERS

__all__ = [
    "FILTERS",
    "EnhancedFrost",
    "EnhancedLee",
    "Frost",
    "GammaMAP",
    "Kuan",
    "Lee",
    "enhanced_frost",
    "enhanced_lee",
    "frost",
    "gamma_map",
    "kuan",
    "lee",
]
