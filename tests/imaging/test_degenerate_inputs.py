"""All-zero items have a defined autofocus result; unavailable devices are refused at the entry."""

from __future__ import annotations

import pytest
import torch

from torchsar.errors import OptionError
from torchsar.imaging import (
    fft2c,
    min_entropy_autofocus,
    point_scene,
    pulse_autofocus,
    pulse_min_entropy,
    speckled_scene,
)
from torchsar.sar import SpotlightGeometry


def _pulses(zero_item: int) -> torch.Tensor:
    b = torch.zeros(3, 4, 6, 6, dtype=torch.complex64)
    b[:, :, 2, 3] = torch.polar(torch.ones(4), torch.tensor([0.0, 1.0, 2.0, 0.5]))
    b[zero_item] = 0
    return b


class TestAllZeroItems:
    def test_min_entropy(self):
        f = torch.zeros(3, 8, 8, dtype=torch.complex64)
        f[:, 2, 5] = 1
        g = fft2c(f)
        g[1] = 0
        r = min_entropy_autofocus(g)
        for x in (r.image, r.phase, r.entropy):
            assert torch.isfinite(x).all()
        assert (r.image[1] == 0).all() and (r.phase[1] == 0).all() and r.entropy[1] == 0
        alone = min_entropy_autofocus(g[[0, 2]])
        assert torch.allclose(r.phase[[0, 2]], alone.phase)
        assert torch.isfinite(
            min_entropy_autofocus(torch.zeros(2, 8, 8, dtype=torch.complex64)).phase
        ).all()

    def test_pulse_autofocus(self):
        b = _pulses(1)
        out = pulse_autofocus(b)
        img, phi, iters = out.image, out.phase, out.iterations
        assert torch.isfinite(img).all() and torch.isfinite(phi).all()
        assert (img[1] == 0).all() and (phi[1] == 0).all() and iters[1] == 0
        alone = pulse_autofocus(b[[0, 2]])  # the others as without the zero item
        assert torch.allclose(img[[0, 2]], alone.image)
        assert torch.allclose(phi[[0, 2]], alone.phase)

    def test_pulse_min_entropy(self):
        out = pulse_min_entropy(_pulses(2))
        img, phi = out.image, out.phase
        assert torch.isfinite(img).all() and torch.isfinite(phi).all()
        assert (img[2] == 0).all() and (phi[2] == 0).all()
        img0 = pulse_min_entropy(torch.zeros(2, 3, 4, 4, dtype=torch.complex64)).image
        assert (img0 == 0).all()


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal without a GPU")
class TestUnavailableDevice:
    def test_scenes(self):
        with pytest.raises(OptionError, match="device = 'cuda' is not available"):
            point_scene(1, size=(8, 8), points=2, device="cuda")
        with pytest.raises(OptionError, match="device = 'cuda:0' is not available"):
            speckled_scene(1, size=(16, 16), device="cuda:0")

    def test_geometry_and_bad_names(self):
        geom = SpotlightGeometry.for_image((16, 16), pixel=1.0)
        with pytest.raises(OptionError, match="not available"):
            geom.wavenumbers(device="cuda")
        with pytest.raises(OptionError, match="must be a torch device"):
            geom.angles(device="gpu please")
        assert geom.angles(device="cpu").device.type == "cpu"
