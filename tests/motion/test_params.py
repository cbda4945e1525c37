from __future__ import annotations

import math
import warnings

import pytest

from tests.motion.conftest import make_params
from torchsar.errors import OptionError
from torchsar.motion import SpotlightConsistencyWarning, SpotlightParams


class TestSpotlightParams:
    def test_table1_derived(self):
        p = make_params()
        c = 299_792_458.0
        assert p.geometry.bandwidth == pytest.approx(150e6)
        assert p.geometry.samples == 180
        assert p.geometry.range_resolution == pytest.approx(c / 300e6)  # ~1 m, not 0.3 m
        assert p.geometry.wavelength == pytest.approx(c / 10e9)
        assert p.geometry.aperture == pytest.approx(p.geometry.wavelength / 0.6)
        assert p.geometry.aperture_time == pytest.approx(
            2 * 1e4 * math.tan(p.geometry.aperture / 2) / 200
        )
        assert p.geometry.pulses == 500
        assert p.geometry.unambiguous_range == pytest.approx(c * 180e6 / 3e14)  # ~180 m
        assert p.geometry.unambiguous_azimuth == pytest.approx(
            p.geometry.wavelength * 1e4 * 200 / 400
        )  # ~150 m
        assert p.geometry.blind_speed == pytest.approx(p.geometry.wavelength * 100)  # ~3 m/s
        assert p.scene_doppler_bandwidth > p.track.prf
        assert p.image_extent == (p.geometry.unambiguous_range, p.geometry.unambiguous_azimuth)
        assert p.pixel_spacing[0] == pytest.approx(p.geometry.unambiguous_range / 1024)

    def test_defaults_warn_about_the_inconsistencies(self):
        with pytest.warns(SpotlightConsistencyWarning) as rec:
            SpotlightParams.from_system()
        text = " ".join(str(r.message) for r in rec)
        assert "150 MHz" in text and "0.3 m" in text
        assert "PRF 200 Hz" in text and "150 m" in text

    def test_consistent_parameters_do_not_warn(self):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            p = SpotlightParams.from_system(
                chirp_rate=5e14, sampling_rate=700e6, prf=400.0, stated_range_resolution=0.3
            )
        assert p.consistency_report() == []
        assert p.image_extent == p.scene_extent

    @pytest.mark.parametrize(
        ("kw", "match"),
        [
            ({"prf": -1.0}, "prf"),
            ({"chirp_rate": 2e14}, "sampling_rate"),
            ({"image_size": (1, 8)}, "image_size"),
            ({"scene_extent": (0.0, 10.0)}, "scene_extent"),
        ],
    )
    def test_errors(self, kw, match):
        with pytest.raises(OptionError, match=match):
            make_params(**kw)
