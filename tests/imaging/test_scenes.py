"""Complex reflectivity scenes for imaging experiments."""

from __future__ import annotations

import pytest

from torchsar.errors import OptionError
from torchsar.imaging.scenes import point_scene, speckled_scene


class TestScenes:
    def test_point_scene(self):
        f, m = point_scene(3, size=(10, 12), points=7, margin=2, seed=0)
        assert f.shape == (3, 1, 10, 12) and m.sum(dim=(1, 2, 3)).tolist() == [7, 7, 7]
        a = f.abs()[m]
        assert (a >= 0.5).all() and (a <= 1.0 + 1e-6).all()
        assert not m[..., :2, :].any() and not m[..., :, -2:].any()

    def test_point_scene_too_many(self):
        with pytest.raises(OptionError, match="points"):
            point_scene(1, size=(2, 2), points=5)

    def test_speckled_scene_statistics(self):
        f, m = speckled_scene(4, size=(64, 64), contrast=10.0, seed=0)
        clutter = f.abs().square()[~m].mean().item()
        target = f.abs().square()[m].mean().item()
        assert clutter == pytest.approx(1.0, rel=0.1)
        assert target == pytest.approx(10.0, rel=0.25)
