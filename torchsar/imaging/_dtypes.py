"""The complex dtype policy of torchsar.imaging (mirrors :func:`torchsar._checks.float_dtype`)."""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar._checks import float_dtype


def complex_dtype(dtype: torch.dtype) -> torch.dtype:
    """complex128 for float64/complex128 input, complex64 for everything else."""
    return torch.complex128 if float_dtype(dtype) == torch.float64 else torch.complex64


def as_complex(x: Tensor) -> Tensor:
    """Return ``x`` as a complex tensor of the policy dtype (no copy when it already is)."""
    return x.to(complex_dtype(x.dtype))
