"""Moving-target detection for single-channel spotlight SAR: looks, focus and subpatches.

The phase histories come from :func:`torchsar.sar.simulate_phase_history` on the
``geometry`` of a :class:`SpotlightParams` (a straight-track collection).
"""

from torchsar.motion.czt import czt
from torchsar.motion.decision import MoverDecision, detect_movers, registration_sigma
from torchsar.motion.defocus import FocusTest, focus_curve, focus_test
from torchsar.motion.focus import azimuth_times, fm_correction, focus_step, refocus, speed_bank
from torchsar.motion.folds import (
    doppler_fold,
    radial_speed_interval,
    unwalk,
    walk_correction,
    walk_rate,
)
from torchsar.motion.formation import polar_format, rereference
from torchsar.motion.looks import (
    LookPlan,
    look_displacement,
    look_images,
    look_plan,
    look_velocity,
)
from torchsar.motion.misregistration import LookTest, look_test
from torchsar.motion.params import SpotlightConsistencyWarning, SpotlightParams
from torchsar.motion.peaks import default_detector, detect_peaks, intensity, window_max
from torchsar.motion.pipeline import MoverReport, find_movers
from torchsar.motion.shift import estimate_shift
from torchsar.motion.streaks import look_interference, streak_level
from torchsar.motion.subpatch import subpatch_centers, subpatch_images
from torchsar.motion.subpatch_movers import SubpatchResult, subpatch_movers
from torchsar.motion.targets import (
    GHOST_MARGIN,
    GHOST_NOISE,
    Bank,
    Targets,
    bank_detect,
    detect_targets,
    smear_ghosts,
)
from torchsar.motion.theory import (
    first_order_offsets,
    folded_speed,
    planar_image_positions,
    scene_positions,
    wrap,
)
from torchsar.motion.tracks import Tracks, associate, measure_displacements
from torchsar.motion.verdict import Verdict, verdict

__all__ = [
    "GHOST_MARGIN",
    "GHOST_NOISE",
    "Bank",
    "FocusTest",
    "LookPlan",
    "LookTest",
    "MoverDecision",
    "MoverReport",
    "SpotlightConsistencyWarning",
    "SpotlightParams",
    "SubpatchResult",
    "Targets",
    "Tracks",
    "Verdict",
    "associate",
    "azimuth_times",
    "bank_detect",
    "czt",
    "default_detector",
    "detect_movers",
    "detect_peaks",
    "detect_targets",
    "doppler_fold",
    "estimate_shift",
    "find_movers",
    "first_order_offsets",
    "fm_correction",
    "focus_curve",
    "focus_step",
    "focus_test",
    "folded_speed",
    "intensity",
    "look_displacement",
    "look_images",
    "look_interference",
    "look_plan",
    "look_test",
    "look_velocity",
    "measure_displacements",
    "planar_image_positions",
    "polar_format",
    "radial_speed_interval",
    "refocus",
    "registration_sigma",
    "rereference",
    "scene_positions",
    "smear_ghosts",
    "speed_bank",
    "streak_level",
    "subpatch_centers",
    "subpatch_images",
    "subpatch_movers",
    "unwalk",
    "verdict",
    "walk_correction",
    "walk_rate",
    "window_max",
    "wrap",
]
