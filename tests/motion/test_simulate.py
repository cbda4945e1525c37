from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from tests.motion.conftest import make_params
from tests.reference.motion import phase_history as phase_history_ref
from torchsar.errors import InputTypeError, ShapeError
from torchsar.sar import add_noise, simulate_phase_history


def _scene(dtype=torch.float64):
    pos = torch.tensor([[[5.0, -3.0], [-20.0, 12.0]]], dtype=dtype)
    vel = torch.tensor([[[0.0, 0.0], [2.0, -1.0]]], dtype=dtype)
    return pos, vel


class TestSimulatePhaseHistory:
    def test_matches_reference_loops(self, tiny):
        pos, vel = _scene()
        g = simulate_phase_history(pos, tiny.geometry, velocities=vel)
        ref = phase_history_ref(tiny, pos[0].numpy(), vel[0].numpy())
        np.testing.assert_allclose(g[0].numpy(), ref, atol=1e-8)

    def test_mover_doppler_and_range_history_match_analytic(self):
        """Pulse-to-pulse phase at f0 gives the Doppler 2/lambda dR/dt of the mover."""
        p = make_params(azimuth_resolution=1.0, prf=2000.0)  # PRF high enough: no aliasing
        y, x, vr, va = 20.0, -10.0, 7.0, 3.0
        pos = torch.tensor([[[y, x]]], dtype=torch.float64)
        g = simulate_phase_history(
            pos, p.geometry, velocities=torch.tensor([[[vr, va]]], dtype=torch.float64)
        )
        t = p.geometry.pulse_times()
        k0 = (p.geometry.samples - 1) // 2  # f = f0 (K even: half a step below)
        f = (
            p.geometry.center_frequency
            + (k0 - (p.geometry.samples - 1) / 2) * p.geometry.frequency_step
        )
        dphi = torch.angle(g[0, 1:, k0] * g[0, :-1, k0].conj())
        tm = (t[1:] + t[:-1]) / 2
        # analytic: phase = -4 pi f / c (R(t) - R0(t)); R from the moving geometry
        rng = y + vr * tm + p.track.scene_range
        azi = x + (va - p.track.platform_speed) * tm
        r_dot = (vr * rng + (va - p.track.platform_speed) * azi) / torch.hypot(rng, azi)
        r0_dot = (
            p.track.platform_speed**2
            * tm
            / torch.hypot(torch.full_like(tm, p.track.scene_range), p.track.platform_speed * tm)
        )
        expected = -4 * math.pi * f / 299_792_458.0 * (r_dot - r0_dot) / p.track.prf
        torch.testing.assert_close(dphi, expected, atol=2e-3, rtol=0)
        # range history from the phase slope over frequency at the aperture centre
        m0 = p.geometry.pulses // 2
        dk = torch.angle(g[0, m0, 1:] * g[0, m0, :-1].conj()).mean()
        dr = -dk * 299_792_458.0 / (4 * math.pi * p.geometry.frequency_step)
        r_t = math.hypot(y + vr * float(t[m0]) + p.track.scene_range, x + (va - 200) * float(t[m0]))
        r_0 = math.hypot(p.track.scene_range, 200 * float(t[m0]))
        assert float(dr) == pytest.approx(r_t - r_0, abs=1e-6)

    @pytest.mark.parametrize("b", [0, 1, 2])
    def test_batch_invariance(self, tiny, b):
        pos, vel = _scene()
        g1 = simulate_phase_history(pos, tiny.geometry, velocities=vel)
        gb = simulate_phase_history(
            pos.expand(b, -1, -1), tiny.geometry, velocities=vel.expand(b, -1, -1)
        )
        assert gb.shape == (b, tiny.geometry.pulses, tiny.geometry.samples)
        if b:
            torch.testing.assert_close(gb, g1.expand(b, -1, -1))

    def test_chunking_does_not_change_the_result(self, tiny):
        pos, vel = _scene()
        a = simulate_phase_history(pos, tiny.geometry, velocities=vel)
        b = simulate_phase_history(pos, tiny.geometry, velocities=vel, chunk_elements=1)
        torch.testing.assert_close(a, b)

    def test_dtype_amplitudes_and_noise(self, tiny):
        pos, _ = _scene(torch.float32)
        amp = torch.tensor([[2.0 + 0j, 0.0 + 0j]])
        g = simulate_phase_history(pos[:, :1], tiny.geometry, amplitudes=amp[:, :1])
        assert g.dtype == torch.complex64
        assert torch.allclose(g.abs(), torch.full_like(g.abs(), 2.0))
        n = add_noise(simulate_phase_history(pos[:, :0], tiny.geometry), std=0.5, seed=0)
        assert float(n.abs().square().mean()) == pytest.approx(0.25, rel=0.1)

    def test_errors(self, tiny):
        with pytest.raises(ShapeError, match=r"\(B, N, 2\)"):
            simulate_phase_history(torch.zeros(3, 2), tiny.geometry)
        with pytest.raises(InputTypeError, match="positions"):
            simulate_phase_history(torch.zeros(1, 2, 2, dtype=torch.long), tiny.geometry)
        with pytest.raises(ShapeError, match="velocities"):
            simulate_phase_history(
                torch.zeros(1, 2, 2), tiny.geometry, velocities=torch.zeros(1, 3, 2)
            )
        with pytest.raises(ShapeError, match="amplitudes"):
            simulate_phase_history(torch.zeros(1, 2, 2), tiny.geometry, amplitudes=torch.ones(2))
