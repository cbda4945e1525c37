"""CFAR detectors: one small function per variant on a shared core.

Every variant returns a :class:`Detection` with ``mask == statistic > threshold``;
:func:`threshold` gives that design threshold for given options without an image.
"""

from torchsar.cfar.ac import ac
from torchsar.cfar.ca import ca
from torchsar.cfar.design import threshold
from torchsar.cfar.g0 import g0
from torchsar.cfar.gamma import gamma
from torchsar.cfar.go import go
from torchsar.cfar.k import k
from torchsar.cfar.lognormal import lognormal
from torchsar.cfar.os_cfar import os, os_mask
from torchsar.cfar.so import so
from torchsar.cfar.two_parameter import two_parameter
from torchsar.cfar.vi import vi
from torchsar.cfar.weibull import weibull
from torchsar.detection import Detection, detection_from

__all__ = [
    "Detection",
    "ac",
    "ca",
    "detection_from",
    "g0",
    "gamma",
    "go",
    "k",
    "lognormal",
    "os",
    "os_mask",
    "so",
    "threshold",
    "two_parameter",
    "vi",
    "weibull",
]
