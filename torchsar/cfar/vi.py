"""Variability-index CFAR (Smith & Varshney 2000) on two halves of the ring."""

from __future__ import annotations

import functools
from collections.abc import Callable
from functools import partial

import numpy as np
import torch
from torch import Tensor

from torchsar import _jit, _triton
from torchsar._checks import check_image, check_positive
from torchsar.cfar.blocks import pinwheel_states
from torchsar.cfar.ca import ca_threshold
from torchsar.cfar.core import (
    conclude,
    finish,
    geometric_cached,
    one_sweep,
    out_dtype,
    prepare,
    ratio,
    square_safe_planes,
    stack_planes,
)
from torchsar.cfar.thresholds import block_factor, ca_factor, keyed_factor_map
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.windows import Ring, Sums, pinwheel_rects, windowed

__all__ = ["rule_states", "vi", "vi_threshold"]

# the clutter estimate each decision uses (codes of the per-pixel rule)
_CA, _GO, _SO, _CA_A, _CA_B = range(5)


def vi(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    k_vi: float = 4.76,
    k_mr: float = 1.806,
    valid: Tensor | None = None,
) -> Detection:
    """Variability-index CFAR: per pixel, pick CA, GO, SO or one-half CA from two halves.

    Halves (each ``N/2`` cells, two pinwheel blocks): ``A`` = top + right blocks (the
    upper-right L of the ring), ``B`` = bottom + left (the lower-left L). Per half the
    variability index ``VI = 1 + s^2 / mean^2`` (unbiased ``s^2``) flags a half as variable
    when ``VI > k_vi``; the mean ratio ``MR = mean_A / mean_B`` says the means differ when it
    leaves ``[1/k_mr, k_mr]``. Decision (Smith & Varshney, Table 1): both uniform and equal
    means -> CA over the ring; both uniform, different means -> GO of the half means; only
    ``A`` variable -> CA on ``B``; only ``B`` variable -> CA on ``A``; both variable -> SO.

    Each rule keeps its own exact factor for exponential clutter (CA: ``ca_factor(n)``,
    one-half CA: ``ca_factor(n_half)``, GO / SO of the halves:
    :func:`~torchsar.cfar.thresholds.block_factor`); the statistic is
    ``I / estimate * alpha_CA(N) / alpha_rule``, so the global threshold is the interior CA
    factor and ``vi`` equals :func:`~torchsar.cfar.ca` exactly where CA is selected.

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g.
        train: training-band width t.
        pfa: design probability of false alarm.
        k_vi: VI threshold. Default 4.76 and ``k_mr`` 1.806 are the values of Smith &
            Varshney's simulations (N = 24, Pfa 1e-3; Section V of the paper).
        k_mr: mean-ratio threshold (> 1).
        valid: optional bool mask of usable cells.

    Returns:
        :class:`Detection` with ``threshold = ca_factor(N, pfa)``.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Smith, M. E., Varshney, P. K., Intelligent CFAR processor based on data variability,
        IEEE TAES 36(3), 837-847, 2000, doi:10.1109/7.869503.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> vi(x, guard=1, train=2).mask.sum().item()
        1
    """
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid, detector="vi", values=False)
    k_vi = check_positive(k_vi, "k_vi")
    k_mr = check_positive(k_mr, "k_mr")
    compiled = vmask is None and not _triton.for_tensor(x) and _jit.for_tensor(x) and x.numel()
    if not compiled:  # the compiled kernel checks the values as it reads them
        check_image(x, "x")
    factor = partial(_rule_factor, pfa=pfa)
    full = vi_threshold(guard=guard, train=train, pfa=pfa, k_vi=k_vi, k_mr=k_mr)
    dtype = out_dtype(x)
    if compiled:
        return _one_sweep(x, ring, pfa, (k_vi, k_mr), full, dtype)

    def statistic(xs: Tensor, sums: list[Sums]) -> Tensor:
        if _jit.for_tensor(xs):
            return _compiled(xs, sums, ring.n, full, factor, (k_vi, k_mr), dtype, vmask is None)
        a, b = _merge(sums[0], sums[1]), _merge(sums[2], sums[3])
        mean_a, mean_b = a.mean(), b.mean()
        rule = _decide(a, b, mean_a, mean_b, k_vi, k_mr)
        est = _estimate(rule, mean_a, mean_b, _merge(a, b))  # the ring: the two halves
        stat = ratio(xs.to(torch.float64), est)
        scale = _rule_scale(rule, a.count, b.count, ring.n, full, factor)
        return finish(stat * scale, a.count + b.count, dtype)

    rects = pinwheel_rects(ring.guard, ring.train)  # the four blocks make the ring
    stat = windowed(x, rects, statistic, valid=vmask, moments=2)
    return conclude(stat, vmask, full)


def _compiled(
    xs: Tensor,
    sums: list[Sums],
    n: int,
    full: float,
    factor: Callable[[tuple[int, ...]], float],
    ks: tuple[float, float],
    dtype: torch.dtype,
    geometric: bool,
) -> Tensor:
    """The statistic of :func:`vi` by :func:`torchsar.cfar._kernels.vi_rule_ratio` (same
    values bit for bit); the rules' factor planes come from :func:`_rule_scale`'s maps
    (remembered where the counts are ``geometric``: no no-data mask)."""
    from torchsar.cfar import _kernels

    k_vi, k_mr = ks

    count = stack_planes([s.count for s in sums[:4]])
    count_a, count_b = count[0] + count[1], count[2] + count[3]
    scale = geometric_cached(
        ("vi", n, full, factor.keywords["pfa"]),
        [count_a, count_b],
        lambda: _rule_maps(count_a, count_b, n, full, factor),
        geometric=geometric,
    )
    out = _kernels.vi_rule_ratio(
        xs.contiguous().numpy(),
        count.numpy(),
        stack_planes([s.s1 for s in sums[:4]]).numpy(),
        stack_planes([s.s2 for s in sums[:4]]).numpy(),
        sums[0].shifts().numpy(),
        k_vi,
        k_mr,
        scale.contiguous().numpy(),
    )
    return finish(torch.from_numpy(out), count_a + count_b, dtype)


def _one_sweep(
    x: Tensor, ring: Ring, pfa: float, ks: tuple[float, float], full: float, dtype: torch.dtype
) -> Detection:
    """:func:`vi` without no-data on the CPU in one sweep per image plane
    (:func:`torchsar._pinwheel_kernels.vi_ratio`: the blocks of ``x`` and its square summed
    directly, not shifted by the plane's mean as the tensor code's sums are, which a few
    bright targets far away would move; the rules' factors from :func:`rule_states`)."""
    from torchsar import _pinwheel_kernels

    g, t = ring.guard, ring.train
    rows, cols, table = rule_states(*x.shape[-2:], g, t, pfa, full)
    planes, rescaled = square_safe_planes(x)
    if rescaled:  # a tiny negative value divided could read as -0.0
        check_image(x.detach(), "x")

    def kernel(planes, thr, out, mask):
        return _pinwheel_kernels.vi_ratio(planes, g, t, *ks, rows, cols, table, thr, out, mask)

    return one_sweep(x, planes, dtype, full, kernel)


@functools.lru_cache(maxsize=32)
def rule_states(
    h: int, w: int, guard: int, train: int, pfa: float, full: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rules' factors ``full / alpha_rule`` in an ``h x w`` image without no-data, as
    tables: ``table[rule, rows[i], cols[j]]`` is pixel ``(i, j)``'s (as
    :func:`_rule_scale` gives it; ``-inf`` where no block has a cell), from the blocks'
    row and column states (:func:`torchsar.cfar.blocks.pinwheel_states`)."""
    n = Ring(guard, train).n
    factor = partial(_rule_factor, pfa=pfa)
    row_states, rows, col_states, cols = pinwheel_states(h, w, guard, train)
    table = np.ones((5, len(row_states), len(col_states)))
    for a, rs in enumerate(row_states):
        for b, cs in enumerate(col_states):
            size = rs * cs
            na, nb = int(size[0] + size[1]), int(size[2] + size[3])
            for rule in range(5):
                if na + nb == 0:
                    table[rule, a, b] = -np.inf
                elif na != n // 2 or nb != n // 2:  # as _rule_maps' float / tensor
                    table[rule, a, b] = full * (1.0 / factor((rule, na, nb)))
                else:
                    table[rule, a, b] = _inner(rule, n, full, factor)
    return rows, cols, table


def vi_threshold(*, guard: int, train: int, pfa: float, k_vi: float, k_mr: float) -> float:
    """The design threshold of :func:`vi` for these options: the interior CA factor (the
    decision thresholds ``k_vi``, ``k_mr`` are only validated)."""
    check_positive(k_vi, "k_vi")
    check_positive(k_mr, "k_mr")
    return ca_threshold(guard=guard, train=train, pfa=pfa, looks=1.0)


def _rule_scale(
    rule: Tensor,
    count_a: Tensor,
    count_b: Tensor,
    n: int,
    full: float,
    factor: Callable[[tuple[int, ...]], float],
) -> Tensor:
    """``full / alpha_rule`` per pixel (float64): the interior factor of each rule where both
    halves are whole (CA there is exactly 1), the exact factor of each pixel's half sizes
    on the border band. The factors are mapped once per rule over the half-size planes
    (without a mask one plane shared by the batch) and each pixel picks its rule's."""
    count_a, count_b = torch.broadcast_tensors(count_a, count_b)
    maps = _rule_maps(count_a, count_b, n, full, factor)
    lead = (1,) * (rule.dim() - count_a.dim())  # counts may lack the leading dims
    maps = maps.reshape(5, *lead, *count_a.shape).expand(5, *rule.shape)
    return torch.gather(maps, 0, rule.unsqueeze(0)).squeeze(0)


def _inner(rule: int, n: int, full: float, factor: Callable[[tuple[int, ...]], float]) -> float:
    """``full / alpha_rule`` with both halves whole (exactly 1 for CA)."""
    return 1.0 if rule == _CA else full / factor((rule, n // 2, n // 2))


def _rule_maps(
    count_a: Tensor,
    count_b: Tensor,
    n: int,
    full: float,
    factor: Callable[[tuple[int, ...]], float],
) -> Tensor:
    """``full / alpha_rule`` at every pixel of the half-size planes, for each of the five
    rules ``(5, ...)``: the interior value, and the exact factor of each pixel's half
    sizes where a half is not whole (with the compiled kernels looked up in
    :func:`_half_tables`, else evaluated per distinct key; ``full`` times the factor's
    reciprocal, as torch divides a number by a tensor)."""
    inner = [_inner(r, n, full, factor) for r in range(5)]
    if count_a.device.type == "cpu" and isinstance(factor, partial) and _jit.enabled():
        from torchsar.cfar import _kernels

        a = count_a.round().long().reshape(-1).numpy()
        b = count_b.round().long().reshape(-1).numpy()
        tables = _half_tables(n, factor.keywords["pfa"])
        for r, p, q in _kernels.pending_halves(a, b, n // 2, tables).tolist():
            tables[r, p, q] = factor((r, p, q))  # (idempotent: threads may share the tables)
        maps = np.empty((5, a.size))
        _kernels.half_maps(a, b, n // 2, tables, np.array(inner), full, maps)
        return torch.from_numpy(maps).view(5, *count_a.shape)
    dev = count_a.device
    maps = torch.stack(
        [torch.full(count_a.shape, v, dtype=torch.float64, device=dev) for v in inner]
    )
    edge = ((count_a != n // 2) | (count_b != n // 2)).nonzero(as_tuple=True)
    if not edge[0].numel():
        return maps
    a, b = count_a[edge], count_b[edge]
    for r in range(5):
        keys = torch.stack([torch.full_like(a, r), a, b], -1)
        maps[r][edge] = full / keyed_factor_map(keys.double(), factor)
    return maps


@functools.lru_cache(maxsize=32)
def _half_tables(n: int, pfa: float) -> np.ndarray:
    """The factors of the five rules by half sizes ``(rule, a, b)``, ``0 <= a, b <= n //
    2``, met so far (NaN: not met yet). A no-data mask gives nearly every pixel half sizes
    of its own, a few hundred pairs, most of them the same from image to image: each
    factor is evaluated once. Entries are only ever filled in, with values that do not
    depend on who computes them, so threads may share the tables."""
    return np.full((5, n // 2 + 1, n // 2 + 1), np.nan)


def _merge(p: Sums, q: Sums) -> Sums:
    """Sums over the union of two disjoint blocks."""
    return Sums(p.count + q.count, p.s1 + q.s1, p.s2 + q.s2, p.shift)


def _variable(s: Sums, mean: Tensor, k_vi: float) -> Tensor:
    """Whether a half is variable: ``VI = 1 + s^2 / mean^2 > k_vi`` (unbiased ``s^2``), or it
    holds at most one cell."""
    vi = 1.0 + ratio(s.var(unbiased=True), mean * mean)
    return (vi > k_vi) | (s.count <= 1)


def _decide(a: Sums, b: Sums, mean_a: Tensor, mean_b: Tensor, k_vi: float, k_mr: float) -> Tensor:
    """The per-pixel rule code (Smith & Varshney's decision table). A half with no counted
    cell (a corner of the image, or masked out) has no mean: the other half's CA is used,
    never SO or GO over an empty half (its mean would read as 0)."""
    var_a, var_b = _variable(a, mean_a, k_vi), _variable(b, mean_b, k_vi)
    differ = (mean_a > k_mr * mean_b) | (mean_b > k_mr * mean_a)
    rule = torch.where(differ, _GO, _CA)
    rule = torch.where(var_a & ~var_b, _CA_B, rule)
    rule = torch.where(var_b & ~var_a, _CA_A, rule)
    rule = torch.where(var_a & var_b, _SO, rule)
    rule = torch.where((a.count == 0) & (b.count > 0), _CA_B, rule)
    return torch.where((b.count == 0) & (a.count > 0), _CA_A, rule)


def _estimate(rule: Tensor, mean_a: Tensor, mean_b: Tensor, ring: Sums) -> Tensor:
    """The clutter estimate of each pixel's rule (float64): one gather over the candidate
    estimates in rule-code order."""
    ring_mean = ring.mean()
    hi, lo = torch.maximum(mean_a, mean_b), torch.minimum(mean_a, mean_b)
    cand = torch.stack(torch.broadcast_tensors(ring_mean, hi, lo, mean_a, mean_b))
    return torch.gather(cand, 0, rule.expand(cand.shape[1:]).unsqueeze(0)).squeeze(0)


def _rule_factor(key: tuple[int, ...], pfa: float) -> float:
    """Exact factor of a rule for half sizes ``(n_a, n_b)``."""
    rule, na, nb = key
    if rule == _CA:
        return ca_factor(na + nb, pfa)
    if rule == _CA_A:
        return ca_factor(na, pfa)
    if rule == _CA_B:
        return ca_factor(nb, pfa)
    return block_factor(tuple(sorted((na, nb))), pfa, "max" if rule == _GO else "min")


SPEC = DetectorSpec(
    name="vi",
    detect=vi,
    order=5,
    options={**WINDOW, "k_vi": 4.76, "k_mr": 1.806},
    threshold=vi_threshold,
)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
