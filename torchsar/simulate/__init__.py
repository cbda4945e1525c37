"""MSTAR-like simulated chips and scenes with ground truth, and SAR clutter models.

These are detection datasets: intensity images ``(B, C, H, W)`` with masks and instances.
Complex reflectivity for phase-history experiments is :mod:`torchsar.imaging.scenes`, and
phase histories themselves are :mod:`torchsar.sar`.
"""

from torchsar.seeding import image_seed
from torchsar.simulate.batch import SimBatch
from torchsar.simulate.chips import chips
from torchsar.simulate.clutter import CLUTTER_MODELS, DEFAULT_SHAPE_PARAM, clutter
from torchsar.simulate.scenes import scenes

__all__ = [
    "CLUTTER_MODELS",
    "DEFAULT_SHAPE_PARAM",
    "SimBatch",
    "chips",
    "clutter",
    "image_seed",
    "scenes",
]
