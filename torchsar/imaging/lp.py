"""L_p-regularised SAR imaging without phase correction (Çetin & Karl 2001); default ``lam``."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import all_finite, check_complex, check_int, check_positive
from torchsar._scale import unit_scale
from torchsar.errors import OptionError
from torchsar.imaging._solver import Settings, State, solve
from torchsar.imaging.operators import FourierOperator, LinearOperator

__all__ = ["default_lam", "lp_image", "resolve_operator"]


def default_lam(
    g: Tensor, *, operator: LinearOperator | None = None, p: float = 1.0, kappa: float = 1.5
) -> Tensor:
    """Data-driven regularisation weight: a threshold at ``kappa`` RMS pixel amplitudes.

    ``rms = ||C^H g|| / sqrt(H W)`` is the RMS amplitude of the conventional image; it does
    not change under phase errors (``C^H`` of a unitary operator preserves energy, and a phase
    error only redistributes it), unlike a median-based noise estimate, which a defocused
    image inflates. ``lam = 2 (kappa rms)^(2-p) / p``, which for ``p = 1`` makes the IRLS fixed
    point a soft threshold at ``tau = kappa * rms``: on a sparse scene (a few per cent of
    bright pixels) this sits far above the noise at any SNR and below the scatterers.
    Computed on the data scaled to unit peak (exactly, by a power of two), so data of any
    magnitude gives the weight scaled by ``scale^(2-p)`` rather than an overflow.

    Args:
        g: phase history ``(B, M, K)``.
        operator: observation operator (default: unitary :class:`FourierOperator`).
        p: the L_p exponent in ``(0, 2]``.
        kappa: threshold in RMS pixel amplitudes (1.5 suits 1-D / separable errors on scenes
            with about 1-3 % bright pixels; :func:`sparse_autofocus` uses 1.0 for ``"2d"``).

    Returns:
        ``(B,)`` real tensor.

    Raises:
        OptionError: ``kappa`` is not a finite number > 0.

    Examples:
        >>> g = torch.ones(2, 8, 8, dtype=torch.complex64)
        >>> default_lam(g)
        tensor([3., 3.])
    """
    operator, g = resolve_operator(g, operator)
    return Problem.of(g, operator, None, None, p, kappa).lam


def _threshold_lam(image: Tensor, p: float, kappa: float) -> Tensor:
    """``lam = 2 (kappa rms)^(2-p) / p`` from the conventional image ``(B, 1, H, W)``."""
    y = image.flatten(1)
    rms = y.norm(dim=1) / math.sqrt(max(1, y.shape[1]))
    rms = rms.clamp_min(torch.finfo(rms.dtype).tiny)
    return 2 * (kappa * rms).pow(2 - p) / p


def _lam_values(lam: float | Tensor, b: int, real: torch.dtype, device) -> Tensor:
    """A given ``lam`` (a number or a scalar / ``(B,)`` tensor, finite and > 0) as ``(B,)``."""
    if isinstance(lam, Tensor):
        if lam.numel() not in (1, b):
            raise OptionError(
                f"lam must be a scalar or have B = {b} values, got {tuple(lam.shape)}"
            )
        if lam.is_complex() or not all_finite(lam) or bool((lam <= 0).any()):
            raise OptionError("lam must be finite and > 0")
        return lam.to(device=device, dtype=real).reshape(-1).expand(b).clone()
    return torch.full((b,), check_positive(lam, "lam"), dtype=real, device=device)


@dataclass(frozen=True)
class Problem:
    """The L_p problem on ``g`` rewritten, exactly, on ``g / scale``.

    ``J(f; g, lam, eps) = scale^2 J(f / scale; g / scale, lam / scale^(2-p), eps / scale^2)``,
    so solving the scaled problem and multiplying the image by ``scale`` (the cost by
    ``scale^2``) solves the original one, with every intermediate value near unit magnitude
    whatever the data's magnitude. ``scale`` is a power of two per item: the scaling itself
    is exact.

    Attributes:
        g: the scaled data ``(B, M, K)``.
        scale: ``(B,)`` powers of two.
        lam: the weight in the caller's units ``(B,)`` (as given, or the default).
        lam_n: the weight of the scaled problem ``(B,)``.
        eps_n: the smoothing of the scaled problem ``(B,)``.
    """

    g: Tensor
    scale: Tensor
    lam: Tensor
    lam_n: Tensor
    eps_n: Tensor

    @staticmethod
    def of(
        g: Tensor,
        op: LinearOperator,
        lam: float | Tensor | None,
        eps: float | None,
        p: float,
        kappa: float = 1.5,
    ) -> Problem:
        """Scale ``g`` and resolve ``lam`` (None: :func:`default_lam`) and ``eps`` (None:
        ``1e-4 tau^2``, ``tau`` the penalty's threshold amplitude) for the scaled problem."""
        b, real = g.shape[0], g.real.dtype
        scale = unit_scale(g).reshape(b)
        gn = g / scale.reshape(b, 1, 1)
        s64 = scale.to(torch.float64)
        if lam is None:
            kappa = check_positive(kappa, "kappa")
            lam_n = _threshold_lam(op.adjoint(gn), p, kappa).to(real)
            lam_t = (lam_n.to(torch.float64) * s64.pow(2 - p)).to(real)
        else:
            lam_t = _lam_values(lam, b, real, g.device)
            lam_n = (lam_t.to(torch.float64) / s64.pow(2 - p)).to(real)
        if eps is not None:
            eps_n = (check_positive(eps, "eps") / s64.square()).to(real)
        elif p < 2:  # tau: the amplitude the penalty thresholds at, p lam / 2 = tau^(2 - p)
            tau = (p * lam_n.to(torch.float64) / 2).pow(1 / (2 - p))
            eps_n = (1e-4 * tau.square()).to(real)
        else:  # p = 2: eps only shifts the cost by a constant
            eps_n = torch.zeros(b, dtype=real, device=g.device)
        return Problem(gn, scale, lam_t, lam_n, eps_n)

    def image(self, f: Tensor) -> Tensor:
        """An image of the scaled problem ``(B, 1, H, W)`` in the caller's units."""
        return f * self.scale.reshape(-1, 1, 1, 1).to(f.real.dtype)

    def cost(self, cost: Tensor) -> Tensor:
        """Costs of the scaled problem ``(B, ...)`` in the caller's units (``scale^2``)."""
        s = self.scale.reshape(-1, *([1] * (cost.dim() - 1))).to(cost.dtype)
        return cost * s * s


def initial_state(g: Tensor, op: LinearOperator, lam: Tensor, eps: Tensor) -> State:
    """Start from the adjoint (conventional) image with zero phase (``lam`` and ``eps``
    ``(B,)``)."""
    b, m, k = g.shape
    f = op.adjoint(g)
    real = g.real.dtype
    return State(
        f=f,
        phi=torch.zeros(b, m, k, dtype=real, device=g.device),
        cols=torch.zeros(b, k, dtype=real, device=g.device),
        lam=lam.reshape(b, 1, 1, 1),
        eps=eps.reshape(b, 1, 1, 1).clamp_min(torch.finfo(real).tiny),
    )


def settings(
    p: float, error: str | None, max_iter: int, tol: float, inner: int, cg: int
) -> Settings:
    """Validate the shared solver options."""
    p = check_positive(p, "p")
    if p > 2:
        raise OptionError(f"p must be in (0, 2], got {p}")
    return Settings(
        p=p,
        error=error,
        max_iter=check_int(max_iter, "max_iter", minimum=0),
        tol=check_positive(tol, "tol", allow_zero=True),
        inner=check_int(inner, "inner", minimum=1),
        cg_iterations=check_int(cg, "cg_iterations", minimum=1),
    )


def lp_image(
    g: Tensor,
    *,
    operator: LinearOperator | None = None,
    p: float = 1.0,
    lam: float | Tensor | None = None,
    eps: float | None = None,
    max_iter: int = 100,
    tol: float = 1e-4,
    cg_iterations: int = 30,
) -> Tensor:
    """Sparsity-driven (L_p-regularised) image without phase correction.

    Minimises ``||g - C f||^2 + lam sum (|f|^2 + eps)^(p/2)`` by half-quadratic iterations
    ``(2 C^H C + p lam Lambda(f)) f = 2 C^H g`` (closed form when ``C^H C = I``, conjugate
    gradient otherwise), per item until the relative change is below ``tol``. Each item is
    solved scaled to unit peak amplitude (an exact rewriting of the same problem), so data
    of any magnitude is imaged without overflow: with the default ``lam`` and ``eps``,
    ``lp_image(s * g) == s * lp_image(g)`` to rounding.

    Args:
        g: complex phase history ``(B, M, K)``; complex128 is computed in double
            precision, every other complex dtype (complex64, complex32) in complex64.
        operator: observation operator (default: unitary :class:`FourierOperator`).
        p: exponent of the L_p penalty, ``0 < p <= 2``.
        lam: regularisation weight: float, ``(B,)`` tensor, or None for :func:`default_lam`.
        eps: smoothing constant of ``|f|`` (default ``1e-4 tau^2`` with ``tau`` the amplitude
            the penalty thresholds at, ``(p lam / 2)^(1 / (2 - p))``, ``lam / 2`` for
            ``p = 1``).
        max_iter: iteration limit.
        tol: relative image change that stops an item.
        cg_iterations: conjugate-gradient iterations per step when ``C^H C != I``.

    Returns:
        Complex image ``(B, 1, H, W)``, complex128 for complex128 data, else complex64.

    Raises:
        InputTypeError, ShapeError: ``g`` is not a complex ``(B, M, K)`` tensor for ``operator``.
        OptionError: invalid option.

    Shape:
        ``(B, M, K) -> (B, 1, H, W)``.

    References:
        Çetin & Karl, IEEE Trans. Image Process. 10(4), 2001, doi:10.1109/83.913596.

    Examples:
        >>> g = torch.zeros(1, 8, 8, dtype=torch.complex64); g[..., :] = 1 / 8
        >>> f = lp_image(g)
        >>> int(f.abs().flatten().argmax())  # the point at the image centre
        36
    """
    op, g = resolve_operator(g, operator)
    cfg = settings(p, None, max_iter, tol, 1, cg_iterations)
    prob = Problem.of(g, op, lam, eps, cfg.p)
    state, _, _ = solve(prob.g, initial_state(prob.g, op, prob.lam_n, prob.eps_n), op, cfg)
    return prob.image(state.f)


def resolve_operator(g: Tensor, operator: LinearOperator | None) -> tuple[LinearOperator, Tensor]:
    """The operator (default: unitary 2-D FFT of ``g``'s shape) and ``g`` validated for it."""
    if operator is None:
        g = check_complex(g, "g", ndim=3)
        operator = FourierOperator(tuple(g.shape[-2:]))
    if not isinstance(operator, LinearOperator):
        raise OptionError(f"operator must be a LinearOperator, got {type(operator).__name__}")
    return operator, operator.check_data(g)
