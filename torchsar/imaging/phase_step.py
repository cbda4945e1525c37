"""Closed-form phase-error steps of sparsity-driven autofocus (seed eqs. 13-19).

Given data ``g`` and the model prediction ``d = C f``, each step minimises
``||exp(-1j phi) g - d||^2`` over the phase exactly: the minimiser of
``||g - exp(1j phi) d||^2`` over one phase shared by a set of samples is
``angle(sum conj(d) g)`` (``atan2``, full quadrant).

These are the inner steps of :func:`~torchsar.imaging.sparse_autofocus`, not autofocus
methods: they return phases only (the methods return an
:class:`~torchsar.imaging.AutofocusResult`).
"""

from __future__ import annotations

from torch import Tensor

__all__ = ["phase_step_1d", "phase_step_2d", "phase_step_separable"]


def phase_step_1d(g: Tensor, d: Tensor) -> Tensor:
    """Per-pulse phase ``phi_m = angle(sum_k conj(d_mk) g_mk)``.

    Args:
        g: observed phase history ``(B, M, K)``.
        d: model prediction ``C f`` ``(B, M, K)``.

    Returns:
        Real ``(B, M)``.

    Examples:
        >>> import torch
        >>> d = torch.ones(1, 2, 3, dtype=torch.complex64)
        >>> phase_step_1d(1j * d, d)
        tensor([[1.5708, 1.5708]])
    """
    return (d.conj() * g).sum(dim=-1).angle()


def phase_step_separable(g: Tensor, d: Tensor, cols: Tensor) -> tuple[Tensor, Tensor]:
    """One alternation of the 2-D separable step: rows given columns, then columns given rows.

    Args:
        g: observed phase history ``(B, M, K)``.
        d: model prediction ``(B, M, K)``.
        cols: current range (column) phase ``(B, K)``.

    Returns:
        ``(rows (B, M), cols (B, K))``; the error is ``rows[:, :, None] + cols[:, None, :]``.

    Examples:
        >>> import torch
        >>> d = torch.ones(1, 2, 2, dtype=torch.complex128)
        >>> r, c = phase_step_separable(d, d, torch.zeros(1, 2, dtype=torch.float64))
        >>> float(r.abs().max() + c.abs().max())
        0.0
    """
    cross = d.conj() * g
    rows = (cross * (-1j * cols[:, None, :]).exp()).sum(dim=-1).angle()
    cols = (cross * (-1j * rows[:, :, None]).exp()).sum(dim=-2).angle()
    return rows, cols


def phase_step_2d(g: Tensor, d: Tensor) -> Tensor:
    """Per-sample phase ``phi_mk = angle(conj(d_mk) g_mk)`` (2-D non-separable).

    Examples:
        >>> import torch
        >>> d = torch.ones(1, 1, 2, dtype=torch.complex64)
        >>> phase_step_2d(-d, d).abs()
        tensor([[[3.1416, 3.1416]]])
    """
    return (d.conj() * g).angle()
