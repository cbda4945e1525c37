"""Whether the compiled CPU kernels (numba) are used.

Two CPU loops of torchsar are sequential by nature and dominated by Python overhead when
written with numpy: the region-growing CFAR's per-seed work (heap growth, rings, test) and
the OS-CFAR's sliding order statistic. Both have numba kernels
(:mod:`torchsar.region._kernels`, :mod:`torchsar.order_statistics._kernels`) that return
the same values bit for bit as the numpy/torch code, which stays as the fallback and as the
reference the tests compare against. So do the window CFARs' per-pixel rules and strip sums
(:mod:`torchsar.cfar._kernels`, :mod:`torchsar._windows_kernels`). The one-sweep kernels
of CA-CFAR without no-data and of the Lee, Kuan and enhanced Lee filters
(:mod:`torchsar._box_kernels`) sum each window directly instead of through integral
images: their float32 results are within an ulp or two of the torch code's (tested), and
closer to the exact sums.

The kernels are imported (and compiled, or loaded from numba's on-disk cache) on first use
only, so ``import torchsar`` does not import numba. Set the environment variable
``TORCHSAR_NUMBA=0`` to never use them; tests switch them with :data:`ENABLED`.
"""

from __future__ import annotations

import importlib.util
import os
import warnings

__all__ = ["ENABLED", "enabled", "for_tensor"]


def installed(module: str) -> bool:
    """Whether the optional package ``module`` is installed (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a broken or blocked install counts as absent
        return False


ENABLED: bool = os.environ.get("TORCHSAR_NUMBA", "1") != "0" and installed("numba")


_IMPORTS: bool | None = None


def _numba_imports() -> bool:
    """Whether ``import numba`` works (tried once, on the first compiled call): an installed
    numba that fails to import (a broken install, a local module shadowing one of its
    dependencies) counts as absent, with one warning, instead of failing the detector."""
    global _IMPORTS
    if _IMPORTS is None:
        try:
            import numba  # noqa: F401
        except Exception as exc:  # any failure of a third-party import: fall back
            warnings.warn(
                f"numba is installed but cannot be imported ({type(exc).__name__}: "
                f"{exc}); torchsar uses its numpy/torch code instead (the same results "
                "to within a float32 ulp or two, slower)",
                UserWarning,
                stacklevel=3,
            )
            _IMPORTS = False
        else:
            _IMPORTS = True
    return _IMPORTS


def enabled() -> bool:
    """Whether the numba kernels are to be used (numba installed, importable and not
    switched off)."""
    return ENABLED and _numba_imports()


def for_tensor(t) -> bool:
    """Whether the numba kernels are to be used on the tensor ``t``: a float32 or float64
    CPU tensor that needs no gradient (the kernels compute values only), with
    :func:`enabled`. Other tensors (other devices and dtypes, autograd) take the torch code."""
    import torch

    return (
        t.device.type == "cpu"
        and t.dtype in (torch.float32, torch.float64)
        and not t.requires_grad
        and enabled()
    )
