"""Slow, obvious reference implementations for torchsar.motion (numpy loops, float64)."""

from __future__ import annotations

import numpy as np

C = 299_792_458.0


def phase_history(params, positions, velocities):
    """g[m, k] = sum_i exp(-j 4 pi f_k / c (R_i(t_m) - R_0(t_m))), one pulse at a time."""
    m_n, k_n = params.geometry.pulses, params.geometry.samples
    g = np.zeros((m_n, k_n), dtype=np.complex128)
    for m in range(m_n):
        t = (m - (m_n - 1) / 2) / params.track.prf
        radar = np.array([-params.track.scene_range, params.track.platform_speed * t])
        r0 = np.linalg.norm(radar)
        for k in range(k_n):
            f = (
                params.geometry.center_frequency
                + (k - (k_n - 1) / 2) * params.geometry.frequency_step
            )
            for p, v in zip(positions, velocities, strict=True):
                r = np.linalg.norm(np.asarray(p) + np.asarray(v) * t - radar)
                g[m, k] += np.exp(-4j * np.pi * f / C * (r - r0))
    return g


def planar_image(params, g, center, ys, xs):
    """Direct planar-wavefront (tomographic) image of data ``g`` referenced to the scene centre.

    I(y, x) = sum_{m,k} g_c[m, k] exp(j kappa_k (y cos(theta_m) + x sin(theta_m))), with
    g_c the data re-referenced to ``center`` and theta_m the look angle to ``center``.
    Evaluated point by point at positions (y, x) relative to ``center``.
    """
    m_n, k_n = g.shape
    t = (np.arange(m_n) - (m_n - 1) / 2) / params.track.prf
    f = (
        params.geometry.center_frequency
        + (np.arange(k_n) - (k_n - 1) / 2) * params.geometry.frequency_step
    )
    kappa = 4 * np.pi * f / C
    radar = np.stack(
        [-params.track.scene_range * np.ones_like(t), params.track.platform_speed * t], 1
    )
    rc = np.linalg.norm(np.asarray(center) - radar, axis=1)
    r0 = np.linalg.norm(radar, axis=1)
    gc = g * np.exp(1j * kappa[None, :] * (rc - r0)[:, None])
    los = (np.asarray(center) - radar) / rc[:, None]  # (range, azimuth) unit vectors
    out = np.zeros((len(ys), len(xs)), dtype=np.complex128)
    for a, y in enumerate(ys):
        for b, x in enumerate(xs):
            proj = y * los[:, 0] + x * los[:, 1]
            out[a, b] = np.sum(gc * np.exp(1j * kappa[None, :] * proj[:, None]))
    return out / g.size


def czt(a, alpha, n_out):
    """Direct sum y[n] = sum_m a[m] exp(j alpha m n)."""
    m = np.arange(a.shape[-1])
    n = np.arange(n_out)
    return a @ np.exp(1j * alpha * m[:, None] * n[None, :])
