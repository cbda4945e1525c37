"""Region-growing CFAR (seed ``region_cfar_nar2011``): grow the target, then test it against
a background ring around the region."""

from torchsar.region.params import PRESETS, RegionOptions, RegionParams
from torchsar.region.search import RegionResult, region_cfar, region_search
from torchsar.region.table import RegionRow, RegionTable

__all__ = [
    "PRESETS",
    "RegionOptions",
    "RegionParams",
    "RegionResult",
    "RegionRow",
    "RegionTable",
    "region_cfar",
    "region_search",
]
