"""Spotlight SAR system parameters (the seed paper's Table 1) and what they really give.

Geometry used throughout :mod:`torchsar.motion`: a 2-D slant plane (grazing angle 0, as in
Table 1). The platform flies a straight line along azimuth at speed ``V``; at slow time ``t``
it is at ``(range, azimuth) = (-R0, V t)``; the scene centre is the origin, so its slant
range at ``t = 0`` (the aperture centre) is ``R0``. Points are written ``(range, azimuth)``
in metres, matching the image axes ``(H, W) = (range, azimuth)``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

from torchsar._checks import OptionError, check_int, check_positive
from torchsar.imaging.geometry import SPEED_OF_LIGHT

__all__ = ["HANN_BROADENING", "SPEED_OF_LIGHT", "SpotlightConsistencyWarning", "SpotlightParams"]

HANN_BROADENING = 1.44  # 3 dB width of the Hann-weighted impulse response / unweighted


class SpotlightConsistencyWarning(UserWarning):
    """The parameters are usable but do not give what the stated figures suggest."""


@dataclass(frozen=True)
class SpotlightParams:
    """Single-channel spotlight SAR parameters with derived quantities.

    Defaults are Table 1 of Yusufoglu & Kartal (2011). Derived quantities are properties;
    constructing a parameter set whose figures contradict each other emits a
    :class:`SpotlightConsistencyWarning` per problem (the defaults emit two: the chirp gives
    150 MHz, i.e. 1 m range resolution rather than the stated 0.3 m, and PRF 200 Hz samples a
    150 m azimuth extent, less than the 200 m scene). :meth:`consistency_report` returns the
    same messages without warning.

    Args:
        center_frequency: carrier ``f0`` in Hz.
        pulse_duration: chirp length ``Tp`` in s.
        prf: pulse repetition frequency in Hz.
        sampling_rate: complex (I/Q) fast-time sampling rate ``fs`` in Hz.
        chirp_rate: sweep rate ``gamma`` in Hz/s; bandwidth ``B = gamma * Tp``.
        platform_speed: ``V`` in m/s.
        scene_range: slant range ``R0`` to the scene centre in m.
        scene_extent: ``(range, azimuth)`` size of the observed scene in m.
        image_size: ``(H, W)`` pixels of one formed image.
        azimuth_resolution: wanted azimuth resolution in m; sets the aperture
            ``dtheta = lambda / (2 rho_a)`` and hence the number of pulses.
        stated_range_resolution: the range resolution the system is claimed to have (Table 1
            says 0.3 m); only used to warn when the chirp cannot deliver it. ``None`` skips it.

    Raises:
        OptionError: a non-positive figure, or a bandwidth larger than the sampling rate.

    References:
        M. H. Yusufoglu, M. Kartal, "Moving target detection in SAR images by using subpatch
        method" (Turkish, seed paper ``subpatch_mtd_yusufoglu_kartal.txt``; DOI not given).
        W. G. Carrara, R. S. Goodman, R. M. Majewski, Spotlight Synthetic Aperture Radar,
        Artech House, 1995.

    Example:
        >>> import warnings
        >>> with warnings.catch_warnings():
        ...     warnings.simplefilter("ignore")
        ...     p = SpotlightParams()
        >>> round(p.bandwidth / 1e6), p.n_samples, p.n_pulses, round(p.range_resolution, 2)
        (150, 180, 500, 1.0)
    """

    center_frequency: float = 10e9
    pulse_duration: float = 1e-6
    prf: float = 200.0
    sampling_rate: float = 180e6
    chirp_rate: float = 1.5e14
    platform_speed: float = 200.0
    scene_range: float = 10e3
    scene_extent: tuple[float, float] = (200.0, 200.0)
    image_size: tuple[int, int] = (1024, 1024)
    azimuth_resolution: float = 0.3
    stated_range_resolution: float | None = 0.3

    def __post_init__(self) -> None:
        for name in (
            "center_frequency",
            "pulse_duration",
            "prf",
            "sampling_rate",
            "chirp_rate",
            "platform_speed",
            "scene_range",
            "azimuth_resolution",
        ):
            check_positive(getattr(self, name), name)
        for i, v in enumerate(self.scene_extent):
            check_positive(v, f"scene_extent[{i}]")
        for i, v in enumerate(self.image_size):
            check_int(v, f"image_size[{i}]", minimum=2)
        if self.bandwidth > self.sampling_rate:
            raise OptionError(
                f"chirp bandwidth chirp_rate * pulse_duration = {self.bandwidth:.4g} Hz must not "
                f"exceed sampling_rate = {self.sampling_rate:.4g} Hz (complex sampling)"
            )
        for message in self.consistency_report():
            warnings.warn(message, SpotlightConsistencyWarning, stacklevel=3)

    # ---- fast time -------------------------------------------------------------------
    @property
    def wavelength(self) -> float:
        """Carrier wavelength ``lambda = c / f0`` in m."""
        return SPEED_OF_LIGHT / self.center_frequency

    @property
    def bandwidth(self) -> float:
        """Swept bandwidth ``B = gamma * Tp`` in Hz."""
        return self.chirp_rate * self.pulse_duration

    @property
    def n_samples(self) -> int:
        """Fast-time samples per pulse ``K = round(fs * Tp)`` (deramped, deskewed)."""
        return max(2, round(self.sampling_rate * self.pulse_duration))

    @property
    def frequency_step(self) -> float:
        """Frequency spacing of the deramped samples ``gamma / fs`` in Hz."""
        return self.chirp_rate / self.sampling_rate

    @property
    def range_resolution(self) -> float:
        """Slant-range resolution ``c / (2 B)`` in m (unweighted)."""
        return SPEED_OF_LIGHT / (2 * self.bandwidth)

    @property
    def unambiguous_range(self) -> float:
        """Range extent sampled without aliasing, ``c fs / (2 gamma)`` in m."""
        return SPEED_OF_LIGHT / (2 * self.frequency_step)

    # ---- slow time -------------------------------------------------------------------
    @property
    def aperture_angle(self) -> float:
        """Integration angle ``lambda / (2 rho_a)`` in rad."""
        return self.wavelength / (2 * self.azimuth_resolution)

    @property
    def aperture_time(self) -> float:
        """Synthetic-aperture time ``2 R0 tan(dtheta / 2) / V`` in s."""
        return 2 * self.scene_range * math.tan(self.aperture_angle / 2) / self.platform_speed

    @property
    def n_pulses(self) -> int:
        """Pulses in the aperture, ``round(T_a * PRF)``."""
        return max(2, round(self.aperture_time * self.prf))

    @property
    def unambiguous_azimuth(self) -> float:
        """Azimuth extent sampled without aliasing, ``lambda R0 PRF / (2 V)`` in m."""
        return self.wavelength * self.scene_range * self.prf / (2 * self.platform_speed)

    @property
    def scene_doppler_bandwidth(self) -> float:
        """Doppler spread of the scene ``2 V W_az / (lambda R0)`` in Hz (must be <= PRF)."""
        return 2 * self.platform_speed * self.scene_extent[1] / (self.wavelength * self.scene_range)

    @property
    def blind_speed(self) -> float:
        """Radial speed whose Doppler equals the PRF, ``lambda PRF / 2`` in m/s."""
        return self.wavelength * self.prf / 2

    # ---- image grid ------------------------------------------------------------------
    @property
    def image_extent(self) -> tuple[float, float]:
        """``(range, azimuth)`` extent of a formed image: the scene, cut to the unambiguous extent.

        Beyond the unambiguous extent the formed image would show every target twice
        (the periodic replica); cutting keeps one copy.
        """
        return (
            min(self.scene_extent[0], self.unambiguous_range),
            min(self.scene_extent[1], self.unambiguous_azimuth),
        )

    @property
    def pixel_spacing(self) -> tuple[float, float]:
        """``(range, azimuth)`` pixel size in m."""
        ext = self.image_extent
        return ext[0] / self.image_size[0], ext[1] / self.image_size[1]

    def consistency_report(self) -> list[str]:
        """Messages describing where the figures contradict each other (empty if consistent)."""
        out = []
        stated = self.stated_range_resolution
        if stated is not None and self.range_resolution > 1.05 * stated:
            out.append(
                f"chirp_rate * pulse_duration gives B = {self.bandwidth / 1e6:.0f} MHz, i.e. "
                f"{self.range_resolution:.2f} m range resolution, not the stated {stated} m "
                f"(that needs {SPEED_OF_LIGHT / (2 * stated) / 1e6:.0f} MHz)"
            )
        if self.unambiguous_range < self.scene_extent[0]:
            out.append(
                f"sampling_rate {self.sampling_rate / 1e6:.0f} MHz samples a range extent of "
                f"{self.unambiguous_range:.0f} m < scene {self.scene_extent[0]:.0f} m; "
                f"images are cut to {self.unambiguous_range:.0f} m"
            )
        if self.unambiguous_azimuth < self.scene_extent[1]:
            out.append(
                f"PRF {self.prf:g} Hz samples an azimuth extent of "
                f"{self.unambiguous_azimuth:.0f} m "
                f"< scene {self.scene_extent[1]:.0f} m (scene Doppler "
                f"{self.scene_doppler_bandwidth:.0f} Hz > PRF); images are cut to "
                f"{self.unambiguous_azimuth:.0f} m and radial speeds alias beyond "
                f"+-{self.blind_speed / 2:.2f} m/s"
            )
        return out
