"""Batched conjugate gradient for Hermitian positive-definite image-step systems."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor


def _dot(a: Tensor, b: Tensor) -> Tensor:
    """Per-item real inner product ``Re <a, b>`` over all but the batch dim, ``(B, 1, ..., 1)``."""
    dims = tuple(range(1, a.dim()))
    return (a.conj() * b).real.sum(dim=dims, keepdim=True)


def conjugate_gradient(
    apply_a: Callable[[Tensor], Tensor], b: Tensor, x0: Tensor, *, iterations: int, tol: float
) -> Tensor:
    """Solve ``A x = b`` per batch item (``A`` Hermitian PD) starting from ``x0``.

    Items whose residual drops below ``tol * ||b||`` stop changing (their step is zeroed).
    """
    x = x0
    r = b - apply_a(x)
    p = r
    rs = _dot(r, r)
    stop = (tol * _dot(b, b).sqrt()).square()
    tiny = torch.finfo(rs.dtype).tiny
    for _ in range(iterations):
        active = rs > stop
        if not bool(active.any()):
            break
        ap = apply_a(p)
        alpha = torch.where(active, rs / _dot(p, ap).clamp_min(tiny), torch.zeros_like(rs))
        x = x + alpha * p
        r = r - alpha * ap
        rs_new = _dot(r, r)
        beta = torch.where(active, rs_new / rs.clamp_min(tiny), torch.zeros_like(rs))
        p = r + beta * p
        rs = rs_new
    return x
