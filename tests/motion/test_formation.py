from __future__ import annotations

import numpy as np
import pytest
import torch

from tests.reference.motion import planar_image
from torchsar.errors import InputTypeError, OptionError, ShapeError
from torchsar.motion import (
    planar_image_positions,
    polar_format,
    subpatch_centers,
    subpatch_images,
)
from torchsar.sar import simulate_phase_history


def peak_position(amp: torch.Tensor, spacing: tuple[float, float]) -> torch.Tensor:
    """Sub-pixel peak of a 2-D amplitude image (Gaussian fit through 3 samples per axis), in m
    relative to the centre pixel (H // 2, W // 2)."""
    h, w = amp.shape
    r, c = divmod(int(amp.flatten().argmax()), w)
    out = []
    for axis, (i, n) in enumerate(((r, h), (c, w))):
        idx = [(i - 1) % n, i, (i + 1) % n]
        v = [amp[j, c] if axis == 0 else amp[r, j] for j in idx]
        lm, l0, lp = (torch.log(x.double() ** 2) for x in v)
        frac = 0.5 * (lm - lp) / (lm - 2 * l0 + lp)
        out.append((i + float(frac) - n // 2) * spacing[axis])
    return torch.tensor(out, dtype=torch.float64)


def _image_near(img, spacing, expected, half=6):
    """Peak position (m) within a window of +-half pixels around ``expected`` (m)."""
    h, w = img.shape
    r = round(expected[0] / spacing[0]) + h // 2
    c = round(expected[1] / spacing[1]) + w // 2
    rows = torch.arange(r - half, r + half + 1) % h
    cols = torch.arange(c - half, c + half + 1) % w
    local = img[rows[:, None], cols[None, :]].abs()
    pos = peak_position(local, spacing)
    return pos + torch.tensor([(r - h // 2) * spacing[0], (c - w // 2) * spacing[1]])


class TestStationaryFocus:
    def test_point_images_at_true_position_in_every_subpatch(self, small):
        centers = subpatch_centers(small)
        offsets = torch.tensor([[3.3, -2.1], [-4.2, 1.7], [2.6, 5.1], [-1.4, -3.8]])
        pos = (centers + offsets.double())[None]
        g = simulate_phase_history(pos, small.geometry)
        imgs = subpatch_images(g, small)[0]
        sp = small.pixel_spacing
        for p in range(4):
            for i in range(4):
                expected = pos[0, i] - centers[p]
                if expected.abs().max() > 65:  # beyond the sampled azimuth half-extent
                    continue
                got = _image_near(imgs[p], sp, expected.tolist())
                planar = planar_image_positions(pos[0, i : i + 1], small, centers[p : p + 1])[0, 0]
                # the planar model predicts the image position (including distortion) ...
                torch.testing.assert_close(got, planar, atol=0.06, rtol=0)
                # ... and near the reference point the image is at the true position
                tol = 0.06 if i == p else 0.6
                torch.testing.assert_close(got, expected, atol=tol, rtol=0)

    def test_matches_direct_planar_sum(self, small):
        pos = torch.tensor([[[12.0, -7.0]]], dtype=torch.float64)
        g = simulate_phase_history(pos, small.geometry)
        center = (10.0, -10.0)
        img = polar_format(g, small, center=center, window="none")[0]
        sp = small.pixel_spacing
        h, w = img.shape
        r0, c0 = round(2.0 / sp[0]) + h // 2, round(3.0 / sp[1]) + w // 2
        rows, cols = np.arange(r0 - 3, r0 + 4), np.arange(c0 - 3, c0 + 4)
        ref = planar_image(
            small, g[0].numpy(), center, (rows - h // 2) * sp[0], (cols - w // 2) * sp[1]
        )
        ours = img[rows[:, None], cols[None, :]].numpy()
        corr = np.abs(np.vdot(ref, ours)) / (np.linalg.norm(ref) * np.linalg.norm(ours))
        assert corr > 0.99
        assert np.abs(ours).max() == pytest.approx(np.abs(ref).max(), rel=0.05)


class TestPolarFormat:
    @pytest.mark.parametrize("b", [0, 1, 2])
    def test_batch_invariance(self, tiny, b):
        pos = torch.tensor([[[3.0, -4.0], [-10.0, 6.0]]])
        g = simulate_phase_history(pos, tiny.geometry)
        one = polar_format(g, tiny, center=(5.0, 5.0))
        many = polar_format(g.expand(b, -1, -1), tiny, center=(5.0, 5.0))
        assert many.shape == (b, 64, 64)
        if b:
            torch.testing.assert_close(many, one.expand(b, -1, -1))

    def test_dtype_follows_input(self, tiny):
        g = simulate_phase_history(torch.zeros(1, 1, 2, dtype=torch.float64), tiny.geometry)
        assert polar_format(g, tiny).dtype == torch.complex128
        assert polar_format(g.to(torch.complex64), tiny).dtype == torch.complex64

    def test_non_contiguous_input(self, tiny):
        g = simulate_phase_history(torch.zeros(2, 1, 2), tiny.geometry)
        nc = torch.cat([g, g], dim=2)[:, :, ::2]
        assert not nc.is_contiguous()
        torch.testing.assert_close(polar_format(nc, tiny), polar_format(g, tiny))

    def test_errors(self, tiny):
        g = simulate_phase_history(torch.zeros(1, 1, 2), tiny.geometry)
        with pytest.raises(InputTypeError, match="complex"):
            polar_format(g.real, tiny)
        with pytest.raises(ShapeError, match=r"\(B, 30, 180\)"):
            polar_format(g[:, 1:], tiny)
        with pytest.raises(OptionError, match="window"):
            polar_format(g, tiny, window="kaiser")

    def test_subpatch_channels_are_polar_format_per_centre(self, tiny):
        g = simulate_phase_history(torch.tensor([[[1.0, 2.0]]]), tiny.geometry)
        imgs = subpatch_images(g, tiny, grid=(1, 2))
        assert imgs.shape == (1, 2, 64, 64)
        for p, c in enumerate(subpatch_centers(tiny, (1, 2))):
            torch.testing.assert_close(imgs[:, p], polar_format(g, tiny, center=tuple(c.tolist())))
