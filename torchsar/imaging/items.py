"""Batch items with nothing to focus (all-zero data) and the device an input asks for."""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar._checks import OptionError

__all__ = ["check_device", "fill_items", "nonzero_items"]


def nonzero_items(x: Tensor) -> Tensor:
    """Bool ``(B,)``: item ``b`` of ``x (B, ...)`` has some non-zero value.

    An all-zero item has no energy to focus: entropy and sparsity objectives have no
    gradient there (``0 * log 0``), so autofocus methods leave it out and report phase 0.

    Example:
        >>> x = torch.zeros(3, 2, 2, dtype=torch.complex64); x[1, 0, 0] = 1
        >>> nonzero_items(x).tolist()
        [False, True, False]
    """
    return (x.flatten(1) != 0).any(1) if x.dim() > 1 else x != 0


def fill_items(live: Tensor, values: Tensor, fill: float = 0.0) -> Tensor:
    """Values of the ``live`` items put back into a batch of ``len(live)`` (``fill`` elsewhere).

    Example:
        >>> fill_items(torch.tensor([False, True]), torch.tensor([[5.0, 6.0]])).tolist()
        [[0.0, 0.0], [5.0, 6.0]]
    """
    out = torch.full(
        (live.numel(), *values.shape[1:]), fill, dtype=values.dtype, device=values.device
    )
    out[live.to(values.device)] = values
    return out


def check_device(device: object, name: str = "device") -> torch.device | None:
    """``device`` as a :class:`torch.device` (``None`` kept), refused when it is unavailable.

    Raises:
        OptionError: not a device, or a CUDA/MPS device on a machine without one.

    Example:
        >>> check_device("cpu")
        device(type='cpu')
    """
    if device is None:
        return None
    try:
        dev = torch.device(device)  # type: ignore[arg-type]
    except (RuntimeError, TypeError):
        raise OptionError(f"{name} must be a torch device such as 'cpu', got {device!r}") from None
    available = {
        "cuda": torch.cuda.is_available,
        "mps": lambda: torch.backends.mps.is_available(),
    }.get(dev.type, lambda: True)
    if not available():
        raise OptionError(
            f"{name} = {device!r} is not available on this machine (no {dev.type} device); "
            f"use device='cpu'"
        )
    return dev
