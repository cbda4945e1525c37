from __future__ import annotations

import math

import pytest
import torch

from torchsar.errors import InputValueError, ShapeError
from torchsar.imaging.backprojection import BackprojectionOperator
from torchsar.sar import SPEED_OF_LIGHT


def _geometry(m=6, k=12, dtype=torch.float64):
    freq = torch.linspace(9.5e9, 9.5e9 + (k - 1) * 5e6, k, dtype=dtype)
    ang = torch.linspace(-0.02, 0.02, m, dtype=dtype)
    ant = torch.stack([1e4 * ang.cos(), 1e4 * ang.sin(), torch.full_like(ang, 5e3)], -1)
    return freq, ant, ant.norm(dim=1)


def _op(upsample=8, **kw):
    freq, ant, r0 = _geometry(**kw)
    x = torch.linspace(-3, 3, 5, dtype=torch.float64)
    y = torch.linspace(-2, 2, 4, dtype=torch.float64)
    return BackprojectionOperator(freq, ant, r0, x, y, upsample=upsample, chunk=4)


def _exact(op, f):
    """Dense exact model ``sum_p f_p exp(-1j U_k dR_mp) / sqrt(M K)``."""
    dr = (op.pixels[None] - op.antenna[:, None]).norm(dim=-1) - op.r0[:, None]  # (M, P)
    u = 4 * math.pi * op.freq / SPEED_OF_LIGHT
    a = torch.polar(torch.ones(1, dtype=torch.float64), -dr[:, None, :] * u[None, :, None])
    return torch.einsum("mkp,bp->bmk", a, f.reshape(f.shape[0], -1)) * op.scale


class TestBackprojection:
    def test_adjoint(self):
        op = _op()
        gen = torch.Generator().manual_seed(0)
        f = torch.randn(2, 1, 4, 5, dtype=torch.complex128, generator=gen)
        g = torch.randn(2, 6, 12, dtype=torch.complex128, generator=gen)
        lhs = (op.forward(f).conj() * g).sum()
        rhs = (f.conj() * op.adjoint(g)).sum()
        torch.testing.assert_close(lhs, rhs, rtol=1e-10, atol=1e-10)

    def test_approximates_exact_model(self):
        f = torch.zeros(1, 1, 4, 5, dtype=torch.complex128)
        f[0, 0, 1, 3] = 1.0
        errs = []
        for up in (4, 32):
            op = _op(upsample=up)
            exact = _exact(op, f)
            errs.append(((op.forward(f) - exact).norm() / exact.norm()).item())
        assert errs[1] < 0.02
        assert errs[1] < errs[0]

    def test_backprojection_focuses_point(self):
        op = _op(m=16, k=32)
        f = torch.zeros(1, 1, 4, 5, dtype=torch.complex128)
        f[0, 0, 2, 1] = 1.0
        img = op.adjoint(_exact(op, f)).abs()
        assert int(img.flatten().argmax()) == 2 * 5 + 1

    def test_shapes_and_batch(self):
        op = _op()
        assert op.forward(torch.zeros(0, 1, 4, 5)).shape == (0, 6, 12)
        g = torch.randn(3, 6, 12, dtype=torch.complex64)
        assert op.adjoint(g).shape == (3, 1, 4, 5)
        torch.testing.assert_close(op.adjoint(g)[1:2], op.adjoint(g[1:2]))

    def test_invalid(self):
        freq, ant, r0 = _geometry()
        x = torch.zeros(2)
        with pytest.raises(ShapeError, match=r"\(M, 3\)"):
            BackprojectionOperator(freq, ant[:, :2], r0, x, x)
        with pytest.raises(InputValueError, match="uniformly spaced"):
            bad = freq.clone()
            bad[-1] += 1e7
            BackprojectionOperator(bad, ant, r0, x, x)


class TestPulseImages:
    def test_sum_is_adjoint_and_phase_rotation(self):
        op = _op()
        g = torch.randn(
            2, 6, 12, dtype=torch.complex128, generator=torch.Generator().manual_seed(2)
        )
        b = op.pulse_images(g)
        assert b.shape == (2, 6, 4, 5)
        torch.testing.assert_close(b.sum(1, keepdim=True), op.adjoint(g))
        phi = torch.rand(2, 6, dtype=torch.float64)
        rotated = (b * torch.polar(torch.ones_like(phi), -phi)[..., None, None]).sum(
            1, keepdim=True
        )
        torch.testing.assert_close(
            rotated, op.adjoint(g * torch.polar(torch.ones_like(phi), -phi)[..., None])
        )

    def test_pulse_autofocus_recovers_synthetic_error(self):
        from torchsar.imaging.fidelity import phase_rmse
        from torchsar.imaging.pulse_autofocus import pulse_autofocus

        op = _op(m=32, k=32)
        f = torch.zeros(1, 1, 4, 5, dtype=torch.complex128)
        f[0, 0, 1, 1], f[0, 0, 3, 4] = 1.0, 0.6j
        g = _exact(op, f)
        phi = torch.rand(1, 32, generator=torch.Generator().manual_seed(3), dtype=torch.float64) * 4
        b = op.pulse_images(g * torch.polar(torch.ones_like(phi), phi)[..., None])
        est = pulse_autofocus(b).phase
        assert phase_rmse(est, phi).item() < 0.2
