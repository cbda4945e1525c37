"""Subpatch moving-target detection for single-channel spotlight SAR (DESIGN §4.6)."""

from torchsar.motion.czt import czt
from torchsar.motion.decision import MoverDecision, detect_movers, registration_sigma
from torchsar.motion.formation import polar_format, rereference
from torchsar.motion.params import SpotlightConsistencyWarning, SpotlightParams
from torchsar.motion.peaks import default_detector, detect_peaks
from torchsar.motion.pipeline import MoverResult, find_movers
from torchsar.motion.shift import estimate_shift
from torchsar.motion.simulate import simulate_phase_history
from torchsar.motion.subpatch import subpatch_centers, subpatch_images
from torchsar.motion.theory import (
    first_order_offsets,
    folded_speed,
    planar_image_positions,
    scene_positions,
)
from torchsar.motion.tracks import Tracks, associate, measure_displacements

__all__ = [
    "MoverDecision",
    "MoverResult",
    "SpotlightConsistencyWarning",
    "SpotlightParams",
    "Tracks",
    "associate",
    "czt",
    "default_detector",
    "detect_movers",
    "detect_peaks",
    "estimate_shift",
    "find_movers",
    "first_order_offsets",
    "folded_speed",
    "measure_displacements",
    "planar_image_positions",
    "polar_format",
    "registration_sigma",
    "rereference",
    "scene_positions",
    "simulate_phase_history",
    "subpatch_centers",
    "subpatch_images",
]
