"""CFAR detectors: one small function per variant on a shared core.

Every variant returns a :class:`Detection` with ``mask == statistic > threshold``.
"""

from torchsar.cfar.ca import ca
from torchsar.cfar.detection import Detection, detection_from
from torchsar.cfar.two_parameter import two_parameter

__all__ = ["Detection", "ca", "detection_from", "two_parameter"]
