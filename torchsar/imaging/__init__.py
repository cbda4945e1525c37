"""Sparsity-driven SAR imaging with joint phase-error correction, autofocus baselines, and the
focus (:mod:`~torchsar.imaging.focus`) and fidelity (:mod:`~torchsar.imaging.fidelity`) metrics
of formed images.

The phase histories these methods focus are simulated by :mod:`torchsar.sar` (one geometry,
one exact simulator); :mod:`torchsar.imaging.scenes` draws the reflectivity they image.
"""

from torchsar.imaging.autofocus import sparse_autofocus
from torchsar.imaging.backprojection import BackprojectionOperator
from torchsar.imaging.fidelity import align, magnitude_correlation, phase_rmse
from torchsar.imaging.focus import contrast, entropy, sharpness, target_to_background
from torchsar.imaging.fourier import fft2c, ifft2c
from torchsar.imaging.lp import default_lam, lp_image
from torchsar.imaging.min_entropy import min_entropy_autofocus
from torchsar.imaging.operators import FourierOperator, LinearOperator
from torchsar.imaging.pga import pga
from torchsar.imaging.phase_errors import (
    apply_phase_error,
    polynomial_phase_error,
    quadratic_phase_error,
    sinusoidal_phase_error,
    uniform_phase_error,
)
from torchsar.imaging.phase_step import phase_step_1d, phase_step_2d, phase_step_separable
from torchsar.imaging.pulse_autofocus import pulse_autofocus, pulse_min_entropy
from torchsar.imaging.result import AutofocusResult, MinEntropyResult, SparseAutofocusResult
from torchsar.imaging.scenes import point_scene, speckled_scene

__all__ = [
    "AutofocusResult",
    "BackprojectionOperator",
    "FourierOperator",
    "LinearOperator",
    "MinEntropyResult",
    "SparseAutofocusResult",
    "align",
    "apply_phase_error",
    "contrast",
    "default_lam",
    "entropy",
    "fft2c",
    "ifft2c",
    "lp_image",
    "magnitude_correlation",
    "min_entropy_autofocus",
    "pga",
    "phase_rmse",
    "phase_step_1d",
    "phase_step_2d",
    "phase_step_separable",
    "point_scene",
    "polynomial_phase_error",
    "pulse_autofocus",
    "pulse_min_entropy",
    "quadratic_phase_error",
    "sharpness",
    "sinusoidal_phase_error",
    "sparse_autofocus",
    "speckled_scene",
    "target_to_background",
    "uniform_phase_error",
]
