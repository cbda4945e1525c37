"""Sparsity-driven SAR imaging with joint phase-error correction, autofocus baselines, metrics."""

from torchsar.imaging.fourier import fft2c, ifft2c
from torchsar.imaging.operators import FourierOperator, LinearOperator

__all__ = ["FourierOperator", "LinearOperator", "fft2c", "ifft2c"]
