from __future__ import annotations

import pytest
import torch

from torchsar.imaging import SpotlightGeometry, add_noise, phase_history, point_scene


@pytest.fixture(scope="session")
def sparse_data():
    """Four 32x32 sparse scenes simulated with the exact polar model at 30 dB SNR."""
    gen = torch.Generator().manual_seed(1234)
    f, mask = point_scene(4, size=(32, 32), points=20, generator=gen)
    g = add_noise(
        phase_history(f, SpotlightGeometry.for_image((32, 32))), snr_db=30.0, generator=gen
    )
    return f, mask, g
