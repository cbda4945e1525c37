from __future__ import annotations

import math

import pytest
import torch

from torchsar.errors import InputTypeError, ShapeError
from torchsar.imaging.focus import contrast, entropy, sharpness, target_to_background


class TestFocusMetrics:
    def test_hand_values(self):
        x = torch.zeros(1, 1, 2, 2)
        x[0, 0, 0, 0] = 1
        assert entropy(x).item() == pytest.approx(0.0, abs=1e-6)
        assert sharpness(x).item() == pytest.approx(1.0)
        assert contrast(x).item() == pytest.approx(math.sqrt(3))
        c = torch.ones(2, 3, 4, 4)
        torch.testing.assert_close(entropy(c), torch.full((2, 3), math.log(16)))
        torch.testing.assert_close(sharpness(c), torch.full((2, 3), 1 / 16))

    def test_focus_ordering(self):
        gen = torch.Generator().manual_seed(0)
        sharp = torch.zeros(1, 1, 16, 16)
        sharp[0, 0, 4, 4], sharp[0, 0, 9, 11] = 5.0, 3.0
        blurred = sharp + 0.2 * torch.rand(1, 1, 16, 16, generator=gen)
        assert entropy(sharp) < entropy(blurred)
        assert contrast(sharp) > contrast(blurred)
        assert sharpness(sharp) > sharpness(blurred)

    def test_zero_image_and_batch(self):
        z = torch.zeros(0, 1, 4, 4)
        assert entropy(z).shape == (0, 1)
        assert torch.isfinite(entropy(torch.zeros(1, 1, 4, 4))).all()

    def test_tbr(self):
        x = torch.ones(1, 1, 4, 4)
        x[0, 0, :2] = 100.0
        m = torch.zeros(1, 1, 4, 4, dtype=torch.bool)
        m[0, 0, :2] = True
        assert target_to_background(x, m).item() == pytest.approx(20.0)

    def test_exceptions(self):
        with pytest.raises(InputTypeError, match="complex"):
            entropy(torch.ones(1, 1, 2, 2, dtype=torch.complex64))
        with pytest.raises(ShapeError, match="same shape"):
            target_to_background(torch.ones(1, 1, 2, 2), torch.ones(1, 1, 3, 2, dtype=torch.bool))
