"""The Table-1 spotlight system of the motion experiments: one geometry plus its image grid.

The collection itself is a :class:`~torchsar.sar.SpotlightGeometry` with a straight
:class:`~torchsar.sar.Track` (2-D slant plane, grazing angle 0, as in Table 1): the platform
flies along azimuth at speed ``V`` and is at ``(range, azimuth) = (-R0, V t)`` at slow time
``t``; the scene centre is the origin. :class:`SpotlightParams` adds only what image
formation needs beside it: the scene extent and the image size. Points are written
``(range, azimuth)`` in metres, matching the image axes ``(H, W) = (range, azimuth)``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import cast

from torchsar._checks import check_int, check_positive
from torchsar.errors import OptionError
from torchsar.sar.geometry import SPEED_OF_LIGHT, SpotlightGeometry, Track

__all__ = ["HANN_BROADENING", "SpotlightConsistencyWarning", "SpotlightParams"]

HANN_BROADENING = 1.44  # 3 dB width of the Hann-weighted impulse response / unweighted


class SpotlightConsistencyWarning(UserWarning):
    """The parameters are usable but do not give what the stated figures suggest."""


@dataclass(frozen=True)
class SpotlightParams:
    """A straight-track spotlight collection and the images formed from it.

    Build it from the system figures with :meth:`from_system` (defaults: Table 1 of
    Yusufoglu & Kartal 2011). Constructing a parameter set whose figures contradict each
    other emits a :class:`SpotlightConsistencyWarning` per problem (Table 1 emits three: the
    chirp gives 150 MHz, i.e. 1 m range resolution rather than the stated 0.3 m; 180
    samples 0.83 MHz apart cover a 180 m range extent, less than the 200 m scene; and PRF
    200 Hz samples a 150 m azimuth extent, less than the 200 m scene).
    :meth:`consistency_report` returns the same messages without warning.

    Attributes:
        geometry: the collection; must have a :class:`~torchsar.sar.Track`.
        scene_extent: ``(range, azimuth)`` size of the observed scene in m.
        image_size: ``(H, W)`` pixels of one formed image.
        stated_range_resolution: the range resolution the system is claimed to have (Table 1
            says 0.3 m); only used to warn when the chirp cannot deliver it. ``None`` skips it.

    Raises:
        OptionError: a geometry without a track, a non-positive extent or a size below 2.

    References:
        M. H. Yusufoglu, M. Kartal, "Moving target detection in SAR images by using subpatch
        method" (Turkish, seed paper ``subpatch_mtd_yusufoglu_kartal.txt``; DOI not given).
        W. G. Carrara, R. S. Goodman, R. M. Majewski, Spotlight Synthetic Aperture Radar,
        Artech House, 1995.

    Examples:
        >>> import warnings
        >>> with warnings.catch_warnings():
        ...     warnings.simplefilter("ignore")
        ...     p = SpotlightParams.from_system()
        >>> g = p.geometry
        >>> round(g.bandwidth / 1e6), g.samples, g.pulses, round(g.range_resolution, 2)
        (150, 180, 500, 1.0)
    """

    geometry: SpotlightGeometry
    scene_extent: tuple[float, float] = (200.0, 200.0)
    image_size: tuple[int, int] = (1024, 1024)
    stated_range_resolution: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.geometry, SpotlightGeometry) or self.geometry.track is None:
            raise OptionError(
                f"geometry must be a SpotlightGeometry with a track, got {self.geometry!r:.80}"
            )
        for i, v in enumerate(self.scene_extent):
            check_positive(v, f"scene_extent[{i}]")
        for i, v in enumerate(self.image_size):
            check_int(v, f"image_size[{i}]", minimum=2)
        for message in self.consistency_report():
            warnings.warn(message, SpotlightConsistencyWarning, stacklevel=4)

    @classmethod
    def from_system(
        cls,
        *,
        center_frequency: float = 10e9,
        pulse_duration: float = 1e-6,
        prf: float = 200.0,
        sampling_rate: float = 180e6,
        chirp_rate: float = 1.5e14,
        platform_speed: float = 200.0,
        scene_range: float = 10e3,
        scene_extent: tuple[float, float] = (200.0, 200.0),
        image_size: tuple[int, int] = (1024, 1024),
        azimuth_resolution: float = 0.3,
        stated_range_resolution: float | None = 0.3,
    ) -> SpotlightParams:
        """Parameters from the system figures of a deramped (dechirped, deskewed) receiver.

        The ``K = max(2, round(fs Tp))`` fast-time samples are ``gamma / fs`` apart
        (bandwidth ``K gamma / fs``, the chirp's ``gamma Tp`` when ``fs Tp`` is whole); the
        aperture ``lambda / (2 rho_a)`` lasts ``T_a = 2 R0 tan(aperture / 2) / V`` and holds
        ``M = max(2, round(T_a PRF))`` pulses.

        Args:
            center_frequency: carrier ``f0`` in Hz.
            pulse_duration: chirp length ``Tp`` in s.
            prf: pulse repetition frequency in Hz.
            sampling_rate: complex (I/Q) fast-time sampling rate ``fs`` in Hz.
            chirp_rate: sweep rate ``gamma`` in Hz/s.
            platform_speed: ``V`` in m/s.
            scene_range: slant range ``R0`` to the scene centre in m.
            scene_extent: ``(range, azimuth)`` size of the observed scene in m.
            image_size: ``(H, W)`` pixels of one formed image.
            azimuth_resolution: wanted azimuth resolution ``rho_a`` in m.
            stated_range_resolution: the claimed range resolution (warned about), or ``None``.

        Raises:
            OptionError: a non-positive figure, or a chirp bandwidth larger than the
                sampling rate.
        """
        for name, value in (
            ("center_frequency", center_frequency),
            ("pulse_duration", pulse_duration),
            ("sampling_rate", sampling_rate),
            ("chirp_rate", chirp_rate),
            ("azimuth_resolution", azimuth_resolution),
        ):
            check_positive(value, name)
        track = Track(platform_speed=platform_speed, scene_range=scene_range, prf=prf)
        if chirp_rate * pulse_duration > sampling_rate:
            raise OptionError(
                f"chirp bandwidth chirp_rate * pulse_duration = {chirp_rate * pulse_duration:.4g} "
                f"Hz must not exceed sampling_rate = {sampling_rate:.4g} Hz (complex sampling)"
            )
        samples = max(2, round(sampling_rate * pulse_duration))
        aperture = SPEED_OF_LIGHT / center_frequency / (2 * azimuth_resolution)
        aperture_time = 2 * scene_range * math.tan(aperture / 2) / platform_speed
        geometry = SpotlightGeometry(
            center_frequency=center_frequency,
            bandwidth=samples * chirp_rate / sampling_rate,
            aperture=aperture,
            pulses=max(2, round(aperture_time * prf)),
            samples=samples,
            chirp_rate=chirp_rate,
            track=track,
        )
        return cls(geometry, scene_extent, image_size, stated_range_resolution)

    @property
    def track(self) -> Track:
        """The platform track of :attr:`geometry`."""
        return cast(Track, self.geometry.track)  # never None: checked at construction

    @property
    def scene_doppler_bandwidth(self) -> float:
        """Doppler spread of the scene ``2 V W_az / (lambda R0)`` in Hz (must be <= PRF)."""
        tr = self.track
        return (
            2
            * tr.platform_speed
            * self.scene_extent[1]
            / (self.geometry.wavelength * tr.scene_range)
        )

    # ---- image grid ------------------------------------------------------------------
    @property
    def image_extent(self) -> tuple[float, float]:
        """``(range, azimuth)`` extent of a formed image: the scene, cut to the unambiguous extent.

        Beyond the unambiguous extent the formed image would show every target twice
        (the periodic replica); cutting keeps one copy.
        """
        return (
            min(self.scene_extent[0], self.geometry.unambiguous_range),
            min(self.scene_extent[1], self.geometry.unambiguous_azimuth),
        )

    @property
    def pixel_spacing(self) -> tuple[float, float]:
        """``(range, azimuth)`` pixel size in m."""
        ext = self.image_extent
        return ext[0] / self.image_size[0], ext[1] / self.image_size[1]

    def consistency_report(self) -> list[str]:
        """Messages describing where the figures contradict each other (empty if consistent)."""
        geo, out = self.geometry, []
        stated = self.stated_range_resolution
        if stated is not None and geo.range_resolution > 1.05 * stated:
            out.append(
                f"the chirp gives B = {geo.bandwidth / 1e6:.0f} MHz, i.e. "
                f"{geo.range_resolution:.2f} m range resolution, not the stated {stated} m "
                f"(that needs {SPEED_OF_LIGHT / (2 * stated) / 1e6:.0f} MHz)"
            )
        if geo.unambiguous_range < self.scene_extent[0]:
            out.append(
                f"sampling every {geo.frequency_step / 1e6:.3g} MHz covers a range extent of "
                f"{geo.unambiguous_range:.0f} m < scene {self.scene_extent[0]:.0f} m; "
                f"images are cut to {geo.unambiguous_range:.0f} m"
            )
        if geo.unambiguous_azimuth < self.scene_extent[1]:
            out.append(
                f"PRF {self.track.prf:g} Hz samples an azimuth extent of "
                f"{geo.unambiguous_azimuth:.0f} m "
                f"< scene {self.scene_extent[1]:.0f} m (scene Doppler "
                f"{self.scene_doppler_bandwidth:.0f} Hz > PRF); images are cut to "
                f"{geo.unambiguous_azimuth:.0f} m; a scatterer at azimuth x moving in range "
                f"at v_r is Doppler-folded when |x - R v_r / V| > "
                f"{geo.unambiguous_azimuth / 2:.0f} m (|v_r| > {geo.blind_speed / 2:.2f} m/s "
                "at the scene centre)"
            )
        return out
