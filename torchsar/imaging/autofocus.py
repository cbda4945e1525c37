"""Sparsity-driven SAR imaging with joint phase-error correction (Önhon & Çetin).

Coordinate descent on ``J(f, phi) = ||g - C(phi) f||^2 + lam sum (|f_i|^2 + eps)^(p/2)``:
a half-quadratic image step and a closed-form phase step for 1-D (per pulse),
2-D separable (per pulse + per frequency) or 2-D non-separable (per sample) errors.
"""

from __future__ import annotations

import dataclasses

import torch
from torch import Tensor

from torchsar._checks import check_choice, check_int
from torchsar.imaging._solver import State, solve
from torchsar.imaging.lp import Problem, initial_state, resolve_operator, settings
from torchsar.imaging.operators import LinearOperator
from torchsar.imaging.result import SparseAutofocusResult
from torchsar.seeding import check_seed, image_seed, make_generator

__all__ = ["ERRORS", "sparse_autofocus"]

ERRORS = ("1d", "2d-separable", "2d")


def sparse_autofocus(
    g: Tensor,
    *,
    error: str = "1d",
    operator: LinearOperator | None = None,
    p: float = 1.0,
    lam: float | Tensor | None = None,
    eps: float | None = None,
    max_iter: int = 100,
    tol: float = 1e-4,
    cg_iterations: int = 30,
    inner: int = 2,
    warmup: int = 10,
    keep: int | None = None,
    restarts: int = 0,
    seed: int = 0,
) -> SparseAutofocusResult:
    """Joint sparsity-driven imaging and phase-error estimation.

    Each iteration: (1) ``inner`` half-quadratic image updates
    ``(2 C^H C + p lam Lambda(f)) f = 2 C^H (exp(-1j phi) g)``; (2) the closed-form phase step
    (:mod:`torchsar.imaging.phase_step`). Items stop individually on relative image change.
    With ``restarts > 0`` the problem is also solved from that many random initial phases
    (uniform in ``[-pi, pi]`` of the error's shape) and each item keeps the lowest final cost.

    Each item is solved scaled to unit peak amplitude (an exact rewriting of the same
    problem: image times the scale, cost times its square), so phase histories of any
    magnitude are focused without overflow; with the default ``lam`` and ``eps`` the
    result for ``s * g`` is ``s`` times the image (the same phase) for ``g``, to rounding.

    Args:
        g: corrupted complex phase history ``(B, M, K)`` (``g = exp(1j phi) C f + noise``);
            complex128 is computed in double precision, every other complex dtype
            (complex64, complex32) in complex64, the dtype of the returned image.
        error: ``"1d"``, ``"2d-separable"`` or ``"2d"``.
        operator: observation operator (default: unitary :class:`FourierOperator`).
        p: L_p exponent in ``(0, 2]``.
        lam: float, ``(B,)`` tensor, or None (data-driven, :func:`default_lam` with
            ``kappa`` 1.5, or 1.0 for ``"2d"``, whose many unknowns need a lower threshold).
        eps: smoothing of ``|f|`` in the penalty (default ``1e-4 tau^2`` with ``tau`` the
            amplitude the penalty thresholds at, ``(p lam / 2)^(1 / (2 - p))``, ``lam / 2``
            for ``p = 1``).
        max_iter: outer iteration limit.
        tol: relative image change that stops an item.
        cg_iterations: CG iterations per image step when ``C^H C != I``.
        inner: image updates per phase update.
        warmup: continuation: over the first ``warmup`` iterations ``lam`` grows
            geometrically from ``lam / 16`` to ``lam`` (keeps the weak coherent part of a
            badly defocused image alive early on); no item stops during the warm-up.
        keep: if given, the image step becomes a hard threshold keeping the ``keep``
            largest pixels (the ``p -> 0`` limit with a known sparsity level; alternating
            projections). Meant for pure phase retrieval (2-D errors spanning ``[-pi, pi]``)
            together with ``restarts``.
        restarts: extra random-phase restarts (best cost kept).
        seed: seed of the restarts' initial phases in ``[0, 2**63)``; item ``i`` draws them
            from its own generator (:func:`~torchsar.seeding.image_seed`
            ``(seed, i)``), so its result does not depend on the batch size.

    Returns:
        :class:`SparseAutofocusResult`: ``image``, ``phase``, ``iterations``, and the final
        ``cost``, its per-iteration ``history`` and the ``lam`` used, all in the units of
        ``g`` (the cost overflows to ``inf`` where ``J`` exceeds the real dtype's range).

    Raises:
        InputTypeError, ShapeError: ``g`` is not complex ``(B, M, K)`` for the operator.
        OptionError: invalid option (message lists allowed values).

    Shape:
        ``(B, M, K) -> image (B, 1, H, W), phase (B, M) or (B, M, K)``.

    References:
        Önhon & Çetin, "A sparsity-driven approach for joint SAR imaging and phase error
        correction", IEEE Trans. Image Process. 21(4), 2012, doi:10.1109/TIP.2011.2174795.

    Examples:
        >>> from torchsar.imaging import fft2c, apply_phase_error
        >>> f = torch.zeros(1, 1, 16, 16, dtype=torch.complex64); f[0, 0, 5, 9] = 1
        >>> phi = torch.linspace(-1, 1, 16)[None] ** 2 * 2.0
        >>> out = sparse_autofocus(apply_phase_error(fft2c(f[:, 0]), phi))
        >>> int(out.image.abs().flatten().argmax()) == 5 * 16 + 9
        True
    """
    error = check_choice(error, "error", ERRORS)
    op, g = resolve_operator(g, operator)
    cfg = settings(p, error, max_iter, tol, inner, cg_iterations)
    cfg = dataclasses.replace(
        cfg,
        warmup=check_int(warmup, "warmup", minimum=0),
        keep=None if keep is None else check_int(keep, "keep", minimum=1),
    )
    restarts = check_int(restarts, "restarts", minimum=0)
    seed = check_seed(seed)
    gens = [make_generator(image_seed(seed, i)) for i in range(g.shape[0] if restarts else 0)]
    prob = Problem.of(g, op, lam, eps, cfg.p, kappa=1.0 if error == "2d" else 1.5)
    g = prob.g  # every item scaled to unit peak: the same problem, no overflow
    best, history, iters = solve(g, initial_state(g, op, prob.lam_n, prob.eps_n), op, cfg)
    best_cost = history[:, -1]
    for _ in range(restarts):
        start = _random_start(g, op, prob, error, gens)
        s, h, it = solve(g, start, op, cfg)
        better = h[:, -1] < best_cost
        best.put(better.nonzero().flatten(), s.take(better))
        history[better] = h[better]
        iters[better] = it[better]
        best_cost = torch.minimum(best_cost, h[:, -1])
    phase = best.phi[..., 0] if error == "1d" else best.phi
    history = prob.cost(history)
    return SparseAutofocusResult(
        image=prob.image(best.f),
        phase=phase,
        iterations=iters,
        cost=history[:, -1].clone(),
        history=history,
        lam=prob.lam,
    )


def _random_start(
    g: Tensor, op: LinearOperator, prob: Problem, error: str, gens: list[torch.Generator]
) -> State:
    """Initial state with a random phase of the error's structure, item ``i`` from ``gens[i]``."""
    s = initial_state(g, op, prob.lam_n, prob.eps_n)
    b, m, k = g.shape
    shape = (m, k) if error == "2d" else (m, 1)
    u = torch.empty(b, *shape, dtype=s.phi.dtype)
    for i, gen in enumerate(gens):
        u[i] = torch.rand(shape, generator=gen, dtype=s.phi.dtype)
    phi = (2 * u - 1) * torch.pi
    s.phi = phi.to(g.device).expand(b, m, k).contiguous()
    s.f = op.adjoint(g * torch.polar(torch.ones_like(s.phi), -s.phi).to(g.dtype))
    return s
