"""Polar-format image formation referenced to an arbitrary scene point.

Re-referencing (the seed's "demodulation to the subpatch centre") multiplies the deramped
data by ``exp(+j kappa (R_c(t) - R_0(t)))`` so it becomes dechirped on point ``c``. The polar
format algorithm (PFA) then treats each sample as the k-space sample
``(K_y, K_x) = kappa (cos theta_m, sin theta_m)``, ``theta_m`` the look angle to ``c``
(planar-wavefront approximation), and inverts the 2-D Fourier transform:

1. range: per pulse, resample ``kappa`` to a uniform ``K_y`` grid (``kappa = K_y / cos theta_m``,
   windowed-sinc interpolation);
2. azimuth: ``K_x = K_y tan theta_m`` is *exactly* uniform in the pulse index for a straight
   track, so each ``K_y`` row is transformed with one chirp-z transform (no interpolation);
3. range: one chirp-z transform over ``K_y`` per image column.

Both chirp-z transforms evaluate the image directly on the requested pixel grid (no zero
padding or cropping). A point target near ``c`` focuses at its position relative to ``c``;
far from ``c`` it is displaced (and defocused) by the wavefront curvature the planar model
ignores: the reason subpatch processing exists, and what
:func:`torchsar.motion.theory.planar_image_positions` predicts.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import check_choice, check_complex, check_int
from torchsar.errors import OptionError, ShapeError
from torchsar.motion.czt import czt
from torchsar.motion.params import SpotlightParams

__all__ = ["polar_format", "rereference", "taper"]

_WINDOWS = ("hann", "none")


def taper(n: int, kind: str, like: Tensor) -> Tensor:
    """Real taper of length ``n`` in ``like``'s real dtype ("hann" or all ones)."""
    if kind == "none":
        return torch.ones(n, dtype=like.real.dtype, device=like.device)
    return torch.hann_window(n, periodic=False, dtype=like.real.dtype, device=like.device)


def rereference(g: Tensor, params: SpotlightParams, center: tuple[float, float]) -> Tensor:
    """Re-reference deramped data from the scene centre to ``center``.

    Returns ``g * exp(+j kappa_k (R_c(t_m) - R_0(t_m)))``: the data a deramp on ``center``
    would have produced. A point at ``center`` becomes a constant.

    Args:
        g: complex ``(B, M, K)`` deramped on the scene centre.
        params: the system.
        center: ``(range, azimuth)`` of the new reference point in m.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> from torchsar.sar import simulate_phase_history
        >>> p = SpotlightParams.from_system(azimuth_resolution=3.0)
        >>> pos = torch.tensor([[[10.0, -5.0]]], dtype=torch.float64)
        >>> g = simulate_phase_history(pos, p.geometry)
        >>> h = rereference(g, p, (10.0, -5.0))
        >>> bool(torch.allclose(h, torch.ones_like(h)))
        True
    """
    check_complex(g, "g", ndim=3)
    return _rereference(g, params, center, slice(None))


def _rereference(
    g: Tensor, params: SpotlightParams, center: tuple[float, float], pulses: slice
) -> Tensor:
    """:func:`rereference` of the pulses ``pulses`` of the aperture."""
    c = torch.tensor([center], dtype=torch.float64, device=g.device)
    dr = params.geometry.differential_ranges(c, pulses=pulses)[0]
    kappa = params.geometry.wavenumbers(device=g.device)
    return g * torch.polar(torch.ones_like(dr[:, None] * kappa), dr[:, None] * kappa).to(g.dtype)


def _check_pulses(pulses: object, n_pulses: int) -> tuple[int, int]:
    """``(start, stop)`` of a pulse range inside ``[0, n_pulses]`` with at least 2 pulses."""
    if pulses is None:
        return 0, n_pulses
    if not (isinstance(pulses, tuple | list) and len(pulses) == 2):
        raise OptionError(f"pulses must be (start, stop) or None, got {pulses!r}")
    start = check_int(pulses[0], "pulses[0]", minimum=0)
    stop = check_int(pulses[1], "pulses[1]", minimum=start + 2)
    if stop > n_pulses:
        raise OptionError(f"pulses[1] must be <= n_pulses = {n_pulses}, got {stop}")
    return start, stop


def _range_grid(kappa: Tensor, cos_t: Tensor) -> tuple[float, float, int]:
    """Uniform ``K_y`` grid ``(start, step, count)`` inside every pulse's band ``kappa cos``."""
    step = float(kappa[1] - kappa[0])
    lo = float(kappa[0]) * float(cos_t.max())
    hi = float(kappa[-1]) * float(cos_t.min())
    return lo, step, math.floor((hi - lo) / step + 1e-9) + 1


def _sinc_resample(g: Tensor, q: Tensor, taps: int = 16) -> Tensor:
    """Hann-windowed sinc interpolation of ``g (B, M, K)`` at fractional indices ``q (M, K')``."""
    k = g.shape[-1]
    base = torch.floor(q).long()
    j = torch.arange(taps, device=g.device) - (taps // 2 - 1)
    idx = base[..., None] + j  # (M, K', taps)
    d = q[..., None] - idx
    w = torch.sinc(d) * torch.cos(d * (math.pi / taps)).square()  # Hann-windowed sinc
    w = torch.where((idx >= 0) & (idx < k), w, torch.zeros_like(w)).to(g.real.dtype)
    src = g[:, torch.arange(g.shape[1], device=g.device)[:, None, None], idx.clamp(0, k - 1)]
    return (src * w).sum(-1) / w.sum(-1).clamp(min=1e-12)


def polar_format(
    g: Tensor,
    params: SpotlightParams,
    *,
    center: tuple[float, float] = (0.0, 0.0),
    size: tuple[int, int] | None = None,
    window: str = "hann",
    pulses: tuple[int, int] | None = None,
) -> Tensor:
    """Form the complex image of deramped data, centred on (and referenced to) ``center``.

    Pixel ``(H // 2, W // 2)`` is ``center``; rows step by ``params.image_extent[0] / H`` in
    range, columns by ``params.image_extent[1] / W`` in azimuth (both increasing). A
    unit-amplitude point at a pixel centre near ``center`` gives a peak of modulus 1.

    Args:
        g: complex ``(B, M, K)`` deramped on the scene centre
            (:func:`~torchsar.sar.simulate_phase_history`).
        params: the system.
        center: ``(range, azimuth)`` reference point in m.
        size: ``(H, W)`` pixels; default ``params.image_size``.
        window: taper applied in both k-space directions, ``"hann"`` or ``"none"``.
        pulses: ``(start, stop)``: ``g`` holds only pulses ``start .. stop - 1`` of the
            aperture (a time sub-aperture, see :func:`~torchsar.motion.looks.look_images`);
            the taper then spans those pulses. Default: the whole aperture.

    Returns:
        complex ``(B, H, W)`` in ``g``'s dtype.

    Raises:
        InputTypeError, ShapeError, InputValueError, OptionError: bad input.

    Shape:
        ``(B, M, K)`` -> ``(B, H, W)``.

    References:
        Carrara, Goodman & Majewski, Spotlight Synthetic Aperture Radar, Artech House 1995,
        ch. 3-4 (PFA); Lanari, "A new method for the compensation of the SAR range cell
        migration based on the chirp z-transform", IEEE TGRS 33(5), 1995,
        doi:10.1109/36.469489.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> from torchsar.sar import simulate_phase_history
        >>> p = SpotlightParams.from_system(azimuth_resolution=1.0, image_size=(64, 64))
        >>> g = simulate_phase_history(torch.zeros(1, 1, 2), p.geometry)
        >>> img = polar_format(g, p)
        >>> divmod(int(img.abs().flatten().argmax()), 64), round(float(img.abs().max()), 3)
        ((32, 32), 1.0)
    """
    check_complex(g, "g", ndim=3)
    check_choice(window, "window", _WINDOWS)
    h, w = params.image_size if size is None else size
    check_int(h, "size[0]", minimum=1)
    check_int(w, "size[1]", minimum=1)
    start, stop = _check_pulses(pulses, params.geometry.pulses)
    if g.shape[1:] != (stop - start, params.geometry.samples):
        raise ShapeError(
            f"g must have shape (B, {stop - start}, {params.geometry.samples}) for these params "
            f"and pulses, got {tuple(g.shape)}"
        )
    t = params.geometry.pulse_times(device=g.device)[start:stop]
    gc = _rereference(g, params, center, slice(start, stop))
    u = params.geometry.look_tangents(center, t)
    kappa = params.geometry.wavenumbers(device=g.device)
    ky0, dk, n_ky = _range_grid(kappa, 1 / torch.sqrt(1 + u * u))
    ky = ky0 + dk * torch.arange(n_ky, dtype=torch.float64, device=g.device)
    q = (ky[None, :] * torch.sqrt(1 + u[:, None] ** 2) - float(kappa[0])) / dk
    rows = _sinc_resample(gc, q).transpose(1, 2)  # (B, K', M)
    dy, dx = params.image_extent[0] / h, params.image_extent[1] / w
    img = _azimuth_transform(rows, ky, u, dx, w, taper(stop - start, window, g))
    return _range_transform(img, ky, dy, h, taper(n_ky, window, g))


def _phase(x: Tensor, dtype: torch.dtype) -> Tensor:
    """``exp(1j * x)`` for float64 ``x``, reduced mod 2 pi first, cast to ``dtype``."""
    return torch.polar(torch.ones_like(x), torch.remainder(x, 2 * math.pi)).to(dtype)


def _azimuth_transform(
    rows: Tensor, ky: Tensor, u: Tensor, dx: float, w: int, taper: Tensor
) -> Tensor:
    """``A[b, i, n] = sum_m taper_m rows[b, i, m] exp(j K_y,i u_m x_n)`` via one CZT per row."""
    x0 = -(w // 2) * dx
    u0, du = float(u[0]), float(u[1] - u[0])
    m = torch.arange(u.numel(), dtype=torch.float64, device=rows.device)
    n = torch.arange(w, dtype=torch.float64, device=rows.device)
    pre = _phase(ky[:, None] * x0 * du * m, rows.dtype) * taper
    post = _phase(ky[:, None] * (x0 * u0 + u0 * dx * n), rows.dtype)
    return czt(rows * pre, ky * dx * du, w) * post / taper.sum()


def _range_transform(a: Tensor, ky: Tensor, dy: float, h: int, taper: Tensor) -> Tensor:
    """``I[b, l, n] = sum_i taper_i A[b, i, n] exp(j K_y,i y_l)`` via one CZT per column."""
    y0 = -(h // 2) * dy
    ky0, dk = float(ky[0]), float(ky[1] - ky[0])
    i = torch.arange(ky.numel(), dtype=torch.float64, device=a.device)
    l_ = torch.arange(h, dtype=torch.float64, device=a.device)
    cols = a.transpose(1, 2) * (_phase(dk * y0 * i, a.dtype) * taper)  # (B, W, K')
    out = czt(cols, torch.tensor(dk * dy, dtype=torch.float64), h)
    out = out * _phase(ky0 * y0 + ky0 * dy * l_, a.dtype)
    return out.transpose(1, 2) / taper.sum()
