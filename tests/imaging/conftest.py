from __future__ import annotations

import pytest

from torchsar.imaging import point_scene
from torchsar.sar import SpotlightGeometry, add_noise, phase_history


@pytest.fixture(scope="session")
def sparse_data():
    """Four 32x32 sparse scenes simulated with the exact polar model at 30 dB SNR."""
    f, mask = point_scene(4, size=(32, 32), points=20, seed=1234)
    g = add_noise(phase_history(f, SpotlightGeometry.for_image((32, 32))), snr_db=30.0, seed=1234)
    return f, mask, g
