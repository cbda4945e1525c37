"""L_p-regularised SAR imaging without phase correction (Çetin & Karl 2001); default ``lam``."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import OptionError, check_complex, check_int, check_positive
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

    Args:
        g: phase history ``(B, M, K)``.
        operator: observation operator (default: unitary :class:`FourierOperator`).
        p: the L_p exponent in ``(0, 2]``.
        kappa: threshold in RMS pixel amplitudes (1.5 suits 1-D / separable errors on scenes
            with about 1-3 % bright pixels; :func:`sparse_autofocus` uses 1.0 for ``"2d"``).

    Returns:
        ``(B,)`` real tensor.

    Example:
        >>> g = torch.ones(2, 8, 8, dtype=torch.complex64)
        >>> default_lam(g)
        tensor([3., 3.])
    """
    operator, g = resolve_operator(g, operator)
    return _threshold_lam(operator.adjoint(g), p, kappa)


def _threshold_lam(image: Tensor, p: float, kappa: float) -> Tensor:
    """``lam = 2 (kappa rms)^(2-p) / p`` from the conventional image ``(B, 1, H, W)``."""
    y = image.flatten(1)
    rms = y.norm(dim=1) / math.sqrt(max(1, y.shape[1]))
    rms = rms.clamp_min(torch.finfo(rms.dtype).tiny)
    return 2 * (kappa * rms).pow(2 - p) / p


def lam_tensor(
    lam: float | Tensor | None, g: Tensor, op: LinearOperator, p: float, kappa: float = 1.5
) -> Tensor:
    """Resolve ``lam`` (None -> :func:`default_lam`) to a ``(B,)`` tensor."""
    b = g.shape[0]
    real = g.real.dtype
    if lam is None:
        return _threshold_lam(op.adjoint(g), p, kappa).to(real)
    if isinstance(lam, Tensor):
        if lam.numel() not in (1, b):
            raise OptionError(
                f"lam must be a scalar or have B = {b} values, got {tuple(lam.shape)}"
            )
        if bool((lam <= 0).any()):
            raise OptionError("lam must be > 0")
        return lam.to(device=g.device, dtype=real).reshape(-1).expand(b).clone()
    return torch.full((b,), check_positive(lam, "lam"), dtype=real, device=g.device)


def initial_state(g: Tensor, op: LinearOperator, lam: Tensor, eps: float | None) -> State:
    """Start from the adjoint (conventional) image with zero phase."""
    b, m, k = g.shape
    f = op.adjoint(g)
    if eps is None:
        scale = (lam / 2).square()  # tau^2 for p = 1; only sets the smoothing scale
        eps_t = 1e-4 * scale
    else:
        eps_t = torch.full_like(lam, check_positive(eps, "eps"))
    real = g.real.dtype
    return State(
        f=f,
        phi=torch.zeros(b, m, k, dtype=real, device=g.device),
        cols=torch.zeros(b, k, dtype=real, device=g.device),
        lam=lam.reshape(b, 1, 1, 1),
        eps=eps_t.reshape(b, 1, 1, 1).clamp_min(torch.finfo(real).tiny),
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
    gradient otherwise), per item until the relative change is below ``tol``.

    Args:
        g: complex phase history ``(B, M, K)``.
        operator: observation operator (default: unitary :class:`FourierOperator`).
        p: exponent of the L_p penalty, ``0 < p <= 2``.
        lam: regularisation weight: float, ``(B,)`` tensor, or None for :func:`default_lam`.
        eps: smoothing constant of ``|f|`` (default: relative to the threshold).
        max_iter: iteration limit.
        tol: relative image change that stops an item.
        cg_iterations: conjugate-gradient iterations per step when ``C^H C != I``.

    Returns:
        Complex image ``(B, 1, H, W)``.

    Raises:
        InputTypeError, ShapeError: ``g`` is not a complex ``(B, M, K)`` tensor for ``operator``.
        OptionError: invalid option.

    Shape:
        ``(B, M, K) -> (B, 1, H, W)``.

    References:
        Çetin & Karl, IEEE Trans. Image Process. 10(4), 2001, doi:10.1109/83.913596.

    Example:
        >>> g = torch.zeros(1, 8, 8, dtype=torch.complex64); g[..., :] = 1 / 8
        >>> f = lp_image(g)
        >>> int(f.abs().flatten().argmax())  # the point at the image centre
        36
    """
    op, g = resolve_operator(g, operator)
    cfg = settings(p, None, max_iter, tol, 1, cg_iterations)
    state = initial_state(g, op, lam_tensor(lam, g, op, cfg.p), eps)
    state, _, _ = solve(g, state, op, cfg)
    return state.f


def resolve_operator(g: Tensor, operator: LinearOperator | None) -> tuple[LinearOperator, Tensor]:
    """The operator (default: unitary 2-D FFT of ``g``'s shape) and ``g`` validated for it."""
    if operator is None:
        g = check_complex(g, "g", ndim=3)
        operator = FourierOperator(tuple(g.shape[-2:]))
    if not isinstance(operator, LinearOperator):
        raise OptionError(f"operator must be a LinearOperator, got {type(operator).__name__}")
    return operator, operator.check_data(g)
