"""Coordinate-descent core shared by :func:`lp_image` and :func:`sparse_autofocus`.

Minimises ``J(f, phi) = ||exp(-1j phi) g - C f||^2 + lam sum (|f|^2 + eps)^(p/2)`` by
alternating half-quadratic (IRLS) image updates with an optional closed-form phase step.
Items of the batch stop individually: once an item's relative image change falls below
``tol`` it is frozen and later iterations only process the still-active items.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar.imaging._cg import conjugate_gradient
from torchsar.imaging.operators import LinearOperator
from torchsar.imaging.phase_step import phase_step_1d, phase_step_2d, phase_step_separable


@dataclass(frozen=True)
class Settings:
    """Solver options (validated by the public entry points)."""

    p: float
    error: str | None
    max_iter: int
    tol: float
    inner: int
    cg_iterations: int
    warmup: int = 0  # iterations over which lam ramps geometrically from lam/16 to lam
    keep: int | None = None  # hard threshold: keep this many largest pixels after each step


@dataclass
class State:
    """Per-item solver state, all with leading batch dim."""

    f: Tensor  # (B, 1, H, W) complex
    phi: Tensor  # (B, M, K) real, full phase estimate
    cols: Tensor  # (B, K) real, column part (2-D separable only)
    lam: Tensor  # (B, 1, 1, 1)
    eps: Tensor  # (B, 1, 1, 1)

    def take(self, idx: Tensor) -> State:
        return State(*(t[idx] for t in (self.f, self.phi, self.cols, self.lam, self.eps)))

    def put(self, idx: Tensor, other: State) -> None:
        for name in ("f", "phi", "cols"):
            getattr(self, name)[idx] = getattr(other, name)


def _rotate(g: Tensor, phi: Tensor) -> Tensor:
    """``exp(-1j phi) g``."""
    return g * torch.polar(torch.ones_like(phi), -phi).to(g.dtype)


def image_update(
    g_corr: Tensor, s: State, op: LinearOperator, cfg: Settings, scale: float = 1.0
) -> Tensor:
    """One half-quadratic step ``(2 C^H C + p lam Lambda(f)) f = 2 C^H g_corr``."""
    weight = cfg.p * scale * s.lam * (s.f.abs().square() + s.eps).pow(cfg.p / 2 - 1)
    rhs = 2 * op.adjoint(g_corr)
    if cfg.keep is not None and op.gram_is_identity:
        return hard_threshold(rhs / 2, cfg.keep)
    if op.gram_is_identity:
        return rhs / (2 + weight)

    def apply_a(x: Tensor) -> Tensor:
        return 2 * op.normal(x) + weight * x

    f = conjugate_gradient(apply_a, rhs, s.f, iterations=cfg.cg_iterations, tol=1e-6)
    return f if cfg.keep is None else hard_threshold(f, cfg.keep)


def hard_threshold(f: Tensor, keep: int) -> Tensor:
    """Keep the ``keep`` largest-magnitude pixels of each item, zero the rest."""
    mag = f.abs().flatten(1)
    keep = min(keep, mag.shape[1])
    if keep == 0 or mag.shape[0] == 0:
        return torch.zeros_like(f) if keep == 0 else f
    kth = mag.topk(keep, dim=1).values[:, -1:]
    return f * (mag >= kth).reshape(f.shape)


def phase_update(g: Tensor, d: Tensor, s: State, error: str) -> tuple[Tensor, Tensor]:
    """Closed-form phase step; returns the full ``(B, M, K)`` phase and the column part."""
    if error == "1d":
        return phase_step_1d(g, d)[..., None].expand_as(s.phi).contiguous(), s.cols
    if error == "2d-separable":
        rows, cols = phase_step_separable(g, d, s.cols)
        return rows[:, :, None] + cols[:, None, :], cols
    return phase_step_2d(g, d), s.cols


def cost(g: Tensor, d: Tensor, s: State, p: float) -> Tensor:
    """``J(f, phi)`` per item, ``(B,)``."""
    fit = (_rotate(g, s.phi) - d).abs().square().sum(dim=(-2, -1))
    reg = (s.f.abs().square() + s.eps).pow(p / 2).sum(dim=(-3, -2, -1))
    return fit + s.lam.flatten() * reg


def _lam_scale(it: int, warmup: int) -> float:
    """Continuation: ``lam`` grows geometrically from ``lam / 16`` to ``lam`` over ``warmup``."""
    if it >= warmup:
        return 1.0
    return 16.0 ** (it / warmup - 1)


def _iterate(
    g: Tensor, s: State, op: LinearOperator, cfg: Settings, it: int
) -> tuple[State, Tensor]:
    """One outer iteration on a (sub)batch; returns the new state and its cost."""
    f_old = s.f
    scale = _lam_scale(it, cfg.warmup)
    for _ in range(cfg.inner):
        s.f = image_update(_rotate(g, s.phi), s, op, cfg, scale)
    d = op.forward(s.f)
    if cfg.error is not None:
        s.phi, s.cols = phase_update(g, d, s, cfg.error)
    change = (s.f - f_old).flatten(1).norm(dim=1) / f_old.flatten(1).norm(dim=1).clamp_min(1e-30)
    return s, torch.stack([cost(g, d, s, cfg.p), change])


def solve(g: Tensor, s: State, op: LinearOperator, cfg: Settings) -> tuple[State, Tensor, Tensor]:
    """Run until every item converged or ``max_iter``; returns state, history, iterations.

    ``history`` is ``(B, max_iter + 1)`` costs (entry 0 = initial), padded with each item's
    final cost after it stopped; ``iterations`` is ``(B,)`` int64.
    """
    b = g.shape[0]
    history = torch.empty(b, cfg.max_iter + 1, dtype=s.lam.dtype, device=g.device)
    history[:, 0] = cost(g, op.forward(s.f), s, cfg.p)
    iterations = torch.zeros(b, dtype=torch.int64, device=g.device)
    active = torch.arange(b, device=g.device)
    for it in range(1, cfg.max_iter + 1):
        if active.numel() == 0:
            history[:, it:] = history[:, it - 1 : it]
            break
        sub, stats = _iterate(g[active], s.take(active), op.select(active), cfg, it)
        s.put(active, sub)
        history[:, it] = history[:, it - 1]
        history[active, it] = stats[0].to(history.dtype)
        iterations[active] = it
        if it >= cfg.warmup:
            active = active[stats[1] > cfg.tol]
    return s, history, iterations
