"""Look images: plan, stationary coincidence, the along-track displacement law, batches."""

from __future__ import annotations

import pytest
import torch

from tests.motion.conftest import make_params
from torchsar.errors import OptionError, ShapeError
from torchsar.motion import (
    estimate_shift,
    look_displacement,
    look_images,
    look_plan,
    look_velocity,
    polar_format,
)
from torchsar.sar import add_noise, simulate_phase_history

STILL = [[-25.0, -20.0], [20.0, -8.0], [-5.0, 6.0]]


@pytest.fixture(scope="module")
def table1():
    """Table 1 aperture (500 pulses, 2.5 s), 128 x 512 images (1.4 m x 0.29 m pixels)."""
    return make_params(image_size=(128, 512))


def _peak(img: torch.Tensor) -> torch.Tensor:
    i = int(img.abs().argmax())
    return torch.tensor([i // img.shape[-1], i % img.shape[-1]])


def _position(img: torch.Tensor, ref: torch.Tensor, pix: torch.Tensor) -> torch.Tensor:
    """Sub-pixel position (pixels) of the peak of ``img`` relative to ``ref``'s peak ``pix``."""
    p = _peak(img)
    h, w = img.shape

    def chip(x, c):
        rows = (c[0] + torch.arange(-8, 8)) % h
        cols = (c[1] + torch.arange(-16, 16)) % w
        return x.abs()[rows][:, cols].double()

    return (p - pix).double() - estimate_shift(chip(ref, pix), chip(img, p), upsample=100)


class TestLookPlan:
    @pytest.mark.parametrize("looks,overlap", [(1, 0.0), (2, 0.0), (3, 0.5), (4, 0.25)])
    def test_equal_looks_spread_over_the_aperture(self, table1, looks, overlap):
        plan = look_plan(table1, looks=looks, overlap=overlap)
        length = plan.stop - plan.start
        assert (length == length[0]).all() and len(length) == looks
        assert plan.start[0] == 0 and plan.stop[-1] <= table1.geometry.pulses
        assert torch.allclose(plan.time, -plan.time.flip(0), atol=1e-12)  # symmetric
        if looks > 1:
            shared = (plan.stop[0] - plan.start[1]).clamp(min=0) / length[0]
            assert abs(float(shared) - overlap) < 0.02

    @pytest.mark.parametrize(
        "kw", [{"looks": 0}, {"overlap": 1.0}, {"overlap": -0.1}, {"looks": 400}]
    )
    def test_bad_options(self, table1, kw):
        with pytest.raises(OptionError):
            look_plan(table1, **kw)


class TestLookImages:
    @pytest.mark.parametrize("looks,overlap", [(2, 0.0), (3, 0.5)])
    def test_stationary_targets_coincide(self, table1, looks, overlap):
        pos = torch.tensor([STILL], dtype=torch.float64)
        x = look_images(
            simulate_phase_history(pos, table1.geometry), table1, looks=looks, overlap=overlap
        )
        h, w = x.shape[-2:]
        for y, az in STILL:  # each target's own neighbourhood (targets are >= 15 m apart)
            r = round(y * h / table1.image_extent[0]) + h // 2
            c = round(az * w / table1.image_extent[1]) + w // 2
            rows, cols = (torch.arange(r - 8, r + 8) % h), (torch.arange(c - 16, c + 16) % w)
            ref = x[0, 0][rows][:, cols]
            for k in range(1, looks):
                d = _position(x[0, k][rows][:, cols], ref, _peak(ref))
                assert d.abs().max() < 0.02, (y, az, k, d)

    def test_along_track_displacement_law(self, table1):
        speeds = [1.0, 4.0, 10.0]
        pos = torch.tensor([[10.0, 5.0]], dtype=torch.float64).expand(3, 1, 2)
        vel = torch.zeros(3, 1, 2, dtype=torch.float64)
        vel[:, 0, 1] = torch.tensor(speeds, dtype=torch.float64)
        x = look_images(simulate_phase_history(pos, table1.geometry, velocities=vel), table1)
        plan = look_plan(table1)
        dt = float(plan.time[1] - plan.time[0])
        for b, speed in enumerate(speeds):
            d = _position(x[b, 1], x[b, 0], _peak(x[b, 0])) * torch.tensor(table1.pixel_spacing)
            theory = look_displacement(speed, dt, table1)
            assert abs(float(d[1]) - theory) < 0.1 * theory
            assert abs(float(d[0])) < 0.05  # no range displacement
            rate = torch.tensor(float(d[1]) / dt)
            assert abs(float(look_velocity(rate, table1)) - speed) < 0.1 * speed

    def test_one_look_is_the_full_image(self, table1):
        g = simulate_phase_history(torch.tensor([[[3.0, 4.0]]]), table1.geometry)
        assert torch.allclose(look_images(g, table1, looks=1)[:, 0], polar_format(g, table1))

    def test_batch_invariance(self, table1):
        pos = torch.tensor([[[3.0, 4.0]], [[-10.0, 12.0]], [[20.0, -30.0]]])
        g = add_noise(simulate_phase_history(pos, table1.geometry), std=0.5, seed=1)
        whole = look_images(g, table1, looks=3)
        parts = torch.cat([look_images(g[i : i + 1], table1, looks=3) for i in range(3)])
        assert torch.allclose(whole, parts, atol=1e-6)
        assert look_images(g[:0], table1).shape == (0, 2, 128, 512)

    def test_polar_format_checks_pulses(self, table1):
        g = simulate_phase_history(torch.zeros(1, 1, 2), table1.geometry)
        with pytest.raises(ShapeError):
            polar_format(g, table1, pulses=(0, 100))
        with pytest.raises(OptionError):
            polar_format(g[:, :1], table1, pulses=(0, 1))
        with pytest.raises(OptionError):
            polar_format(g, table1, pulses=(10, 600))


def test_look_velocity_inverts_the_law():
    p = make_params()
    v = torch.linspace(-16, 16, 33, dtype=torch.float64)
    assert torch.allclose(look_velocity(look_displacement(v, 1.0, p), p), v, atol=1e-9)
