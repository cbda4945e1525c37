"""Whether the Triton GPU kernels are used.

On a CUDA device, CA-CFAR and OS-CFAR without no-data run as fused Triton kernels
(:mod:`torchsar._gpu_kernels`): one pass over the image that sums each ring directly
(CA) or counts it (OS) and writes the statistic and the mask, instead of the integral images
and the per-pixel sort of the tensor code. Other devices, dtypes and inputs (no-data masks,
autograd) take the tensor code, which stays the reference the tests compare against.

The kernels are imported (and compiled by Triton, or loaded from its cache) on first use
only, so ``import torchsar`` does not import Triton. Set ``TORCHSAR_TRITON=0`` to never use
them. Without a GPU the same kernels run in Triton's interpreter (``TRITON_INTERPRET=1`` set
before they are first imported): the default test run compares them there with the CPU code.
"""

from __future__ import annotations

import os
import warnings

from torchsar._jit import installed

__all__ = ["ENABLED", "enabled", "for_tensor", "kernels", "works_on"]


ENABLED: bool = os.environ.get("TORCHSAR_TRITON", "1") != "0" and installed("triton")

_KERNELS: object | None = None
_FAILED = False


def kernels():
    """The module of Triton kernels (imported once), or ``None`` when Triton is switched off,
    absent or fails to import (one warning; the tensor code is used instead)."""
    global _KERNELS, _FAILED
    if not ENABLED or _FAILED:
        return None
    if _KERNELS is None:
        try:
            from torchsar import _gpu_kernels
        except Exception as exc:  # any failure of a third-party import: fall back
            warnings.warn(
                f"triton is installed but its kernels cannot be loaded ({type(exc).__name__}: "
                f"{exc}); torchsar uses its tensor code on the GPU instead (the same masks "
                "up to near-ties, slower)",
                UserWarning,
                stacklevel=3,
            )
            _FAILED = True
            return None
        _KERNELS = _gpu_kernels
    return _KERNELS


def enabled() -> bool:
    """Whether the Triton kernels are to be used (installed, importable, not switched off)."""
    return kernels() is not None


_PLANE_LIMIT = 1 << 31  # pixels of one image plane: the kernels index a plane in int32
_WORKS: dict[str, bool] = {}


def works_on(device) -> bool:
    """Whether the kernels compile and run on ``device`` (tried once per device on a tiny
    image): Triton needs a C compiler for its launcher and a driver it supports, which a
    machine may lack; then one warning, and the tensor code from there on."""
    key = str(device)
    if key not in _WORKS:
        import numpy as np
        import torch

        try:
            x = torch.ones(1, 1, 8, 8, device=device)
            thr = torch.tensor(1.0, device=device)
            kernels().ring_ratio(x, 1, 1, np.ones(9), thr)[1].cpu()
            _WORKS[key] = True
        except Exception as exc:  # a missing compiler or driver: any failure, fall back
            first = str(exc).splitlines()[0] if str(exc) else ""
            warnings.warn(
                f"torchsar's Triton kernels do not run on {key} ({type(exc).__name__}: "
                f"{first}); the tensor code is used there instead (the same masks up to "
                "near-ties, slower)",
                UserWarning,
                stacklevel=3,
            )
            _WORKS[key] = False
    return _WORKS[key]


def for_tensor(t) -> bool:
    """Whether the Triton kernels are to be used on ``t``: a float32 CUDA tensor that needs
    no gradient, whose image planes have fewer than 2^31 pixels, with :func:`enabled` and
    :func:`works_on` its device."""
    import torch

    return (
        t.device.type == "cuda"
        and t.dtype == torch.float32
        and not t.requires_grad
        and t.dim() >= 2
        and t.shape[-2] * t.shape[-1] < _PLANE_LIMIT
        and enabled()
        and works_on(t.device)
    )
