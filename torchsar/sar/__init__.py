"""One spotlight SAR world: the collection geometry and the exact phase-history simulator.

Used by :mod:`torchsar.imaging` (polar-raster experiments) and :mod:`torchsar.motion`
(straight-track experiments with moving scatterers).
"""

from torchsar.sar.geometry import SPEED_OF_LIGHT, SpotlightGeometry, Track
from torchsar.sar.noise import add_noise, image_noise_std
from torchsar.sar.phase_history import phase_history, simulate_phase_history

__all__ = [
    "SPEED_OF_LIGHT",
    "SpotlightGeometry",
    "Track",
    "add_noise",
    "image_noise_std",
    "phase_history",
    "simulate_phase_history",
]
