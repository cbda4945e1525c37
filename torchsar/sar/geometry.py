"""One spotlight SAR collection: carrier, band, aperture, sampling and (optionally) the track.

A deramped spotlight phase history is complex ``(B, M pulses, K samples)``. Sample ``k`` has
frequency ``f_k`` and two-way wavenumber ``U_k = 4 pi f_k / c``; a scatterer contributes
``a exp(-1j U_k dR_m)`` where ``dR_m`` is its differential range at pulse ``m`` (its range
minus the range to the scene centre, the deramp reference). Positions are
``(range, cross-range)`` in metres from the scene centre, velocities ``(range,
cross-range)`` in m/s. Two range models share this one type:

- **polar raster** (``track=None``, the far-field model of imaging experiments): pulse ``m``
  looks at azimuth ``th_m = (m - M//2) * aperture / M`` and ``dR = x cos th + y sin th``
  (plane wavefronts). Pulses and samples are centred on the DFT index ``(M//2, K//2)``, so
  the centred DFT grid has pixel spacing ``range_resolution`` (columns) and
  ``cross_range_resolution`` (rows): :func:`~torchsar.imaging.ifft2c` reconstructs the data
  approximately (the polar raster is not Cartesian; no inverse crime).
- **straight track** (a :class:`Track`, the exact near-field model of motion experiments):
  the platform flies along cross-range at speed ``V`` and is at ``(-R0, V t)`` at slow time
  ``t_m = (m - (M - 1) / 2) / PRF``; ranges are exact (no far-field approximation) and a
  moving scatterer is at ``p + v t`` at pulse ``m``. Pulses and samples are symmetric about
  the aperture and band centres, so ``t = 0`` is mid-aperture and ``center_frequency`` the
  band centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import check_device, check_int, check_positive
from torchsar.errors import OptionError

__all__ = ["SPEED_OF_LIGHT", "SpotlightGeometry", "Track"]

SPEED_OF_LIGHT = 299_792_458.0  # m/s


@dataclass(frozen=True)
class Track:
    """The straight platform track of a near-field spotlight collection.

    Attributes:
        platform_speed: ``V`` in m/s along cross-range.
        scene_range: slant range ``R0`` from the track to the scene centre in m.
        prf: pulse repetition frequency in Hz.
    """

    platform_speed: float
    scene_range: float
    prf: float

    def __post_init__(self) -> None:
        for name in ("platform_speed", "scene_range", "prf"):
            check_positive(getattr(self, name), name)


@dataclass(frozen=True)
class SpotlightGeometry:
    """Sampling of a deramped spotlight phase history ``(B, M, K)`` (see the module docstring).

    Attributes:
        center_frequency: carrier ``fc`` in Hz.
        bandwidth: sampled bandwidth ``B`` in Hz (``K`` samples ``B / K`` apart).
        aperture: integration angle in radians; it sets the cross-range resolution
            ``c / (2 fc aperture)`` (with a track, the pulses are the track's and
            ``aperture`` is the angle their count was chosen for).
        pulses: number of pulses ``M``.
        samples: number of frequency samples ``K``.
        chirp_rate: sweep rate ``gamma`` of the transmitted chirp in Hz/s (instantaneous
            frequency ``f0 + gamma t``); used only for the residual video phase (RVP).
        track: the platform track (exact near-field ranges, movers); ``None`` for the
            far-field polar raster.

    Examples:
        >>> geo = SpotlightGeometry.for_image((32, 32), pixel=1.0)
        >>> round(geo.range_resolution, 6), round(geo.cross_range_resolution, 6)
        (1.0, 1.0)
    """

    center_frequency: float
    bandwidth: float
    aperture: float
    pulses: int
    samples: int
    chirp_rate: float = 0.0
    track: Track | None = None

    def __post_init__(self) -> None:
        for name in ("center_frequency", "bandwidth", "aperture"):
            check_positive(getattr(self, name), name)
        check_int(self.pulses, "pulses", minimum=1)
        check_int(self.samples, "samples", minimum=1)
        if self.bandwidth >= 2 * self.center_frequency:
            raise OptionError(
                f"bandwidth must be < 2 * center_frequency, got {self.bandwidth:g} Hz "
                f"for fc = {self.center_frequency:g} Hz"
            )
        if self.track is not None and not isinstance(self.track, Track):
            raise OptionError(f"track must be a Track or None, got {self.track!r:.60}")

    @classmethod
    def for_image(
        cls,
        shape: tuple[int, int],
        *,
        pixel: float = 1.0,
        center_frequency: float = 10e9,
        chirp_rate: float = 0.0,
    ) -> SpotlightGeometry:
        """Polar raster whose DFT pixel grid is ``shape`` = ``(M, K)`` with square ``pixel`` (m)."""
        check_positive(pixel, "pixel")
        check_positive(center_frequency, "center_frequency")
        m, k = shape
        return cls(
            center_frequency=center_frequency,
            bandwidth=SPEED_OF_LIGHT / (2 * pixel),
            aperture=SPEED_OF_LIGHT / (2 * center_frequency * pixel),
            pulses=m,
            samples=k,
            chirp_rate=chirp_rate,
        )

    # ---- resolution and sampling ---------------------------------------------------------
    @property
    def wavelength(self) -> float:
        """Carrier wavelength ``c / fc`` in m."""
        return SPEED_OF_LIGHT / self.center_frequency

    @property
    def frequency_step(self) -> float:
        """Spacing ``B / K`` of the frequency samples in Hz."""
        return self.bandwidth / self.samples

    @property
    def range_resolution(self) -> float:
        """Range resolution ``c / (2 B)`` in m (unweighted; the polar raster's column spacing)."""
        return SPEED_OF_LIGHT / (2 * self.bandwidth)

    @property
    def cross_range_resolution(self) -> float:
        """Cross-range resolution ``c / (2 fc aperture)`` in m (the polar raster's row spacing)."""
        return SPEED_OF_LIGHT / (2 * self.center_frequency * self.aperture)

    @property
    def unambiguous_range(self) -> float:
        """Range extent sampled without aliasing, ``c / (2 B / K)`` in m."""
        return SPEED_OF_LIGHT / (2 * self.frequency_step)

    def _centre(self, n: int) -> float:
        """Index of the reference sample: DFT centre (polar raster) or midpoint (track)."""
        return n // 2 if self.track is None else (n - 1) / 2

    def frequencies(self, *, device: torch.device | str | None = None) -> Tensor:
        """Sample frequencies ``f_k`` in Hz, float64 ``(K,)``."""
        k = torch.arange(self.samples, dtype=torch.float64, device=check_device(device))
        return self.center_frequency + (k - self._centre(self.samples)) * self.frequency_step

    def wavenumbers(
        self, *, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None
    ) -> Tensor:
        """Two-way wavenumbers ``U_k = 4 pi f_k / c`` in rad/m, shape ``(K,)``."""
        return (4 * math.pi * self.frequencies(device=device) / SPEED_OF_LIGHT).to(dtype)

    def angles(
        self, *, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None
    ) -> Tensor:
        """Pulse azimuths ``th_m`` in radians, shape ``(M,)`` (``-atan(V t_m / R0)`` on a track)."""
        if self.track is not None:
            t = self.pulse_times(device=device)
            return torch.atan(-self.track.platform_speed * t / self.track.scene_range).to(dtype)
        m = torch.arange(self.pulses, dtype=dtype, device=check_device(device))
        return (m - self.pulses // 2) * (self.aperture / self.pulses)

    def pixel_positions(
        self, shape: tuple[int, int], *, dtype: torch.dtype = torch.float64, device=None
    ) -> tuple[Tensor, Tensor]:
        """Polar-raster DFT grid: cross-range ``y`` (rows, ``(H,)``), range ``x`` (``(W,)``)."""
        h, w = shape
        y = (torch.arange(h, dtype=dtype, device=device) - h // 2) * self.cross_range_resolution
        x = (torch.arange(w, dtype=dtype, device=device) - w // 2) * self.range_resolution
        return y, x

    # ---- the track -----------------------------------------------------------------------
    def _track(self) -> Track:
        if self.track is None:
            raise OptionError(
                "this needs a straight-track geometry (SpotlightGeometry(..., track=Track(...))); "
                "the polar raster has no slow time"
            )
        return self.track

    @property
    def aperture_time(self) -> float:
        """Synthetic-aperture time ``2 R0 tan(aperture / 2) / V`` in s (track only)."""
        tr = self._track()
        return 2 * tr.scene_range * math.tan(self.aperture / 2) / tr.platform_speed

    @property
    def unambiguous_azimuth(self) -> float:
        """Cross-range extent sampled without aliasing, ``lambda R0 PRF / (2 V)`` in m."""
        tr = self._track()
        return self.wavelength * tr.scene_range * tr.prf / (2 * tr.platform_speed)

    @property
    def blind_speed(self) -> float:
        """Radial speed whose Doppler equals the PRF, ``lambda PRF / 2`` in m/s (track only)."""
        return self.wavelength * self._track().prf / 2

    def pulse_times(self, *, device: torch.device | str | None = None) -> Tensor:
        """Slow times ``t_m = (m - (M - 1) / 2) / PRF`` in s, float64 ``(M,)`` (track only)."""
        prf = self._track().prf
        m = torch.arange(self.pulses, dtype=torch.float64, device=check_device(device))
        return (m - (self.pulses - 1) / 2) / prf

    def slant_ranges(
        self, points: Tensor, times: Tensor, velocities: Tensor | None = None
    ) -> Tensor:
        """Exact range of each point at each slow time, float64 ``(..., M)`` (track only).

        Args:
            points: ``(..., 2)`` positions ``(range, cross-range)`` at ``t = 0`` in m.
            times: ``(M,)`` slow times in s.
            velocities: optional ``(..., 2)`` constant velocities in m/s.
        """
        tr = self._track()
        p, t = points.to(torch.float64), times.to(torch.float64)
        rng = p[..., 0:1] + tr.scene_range
        azi = p[..., 1:2] - tr.platform_speed * t
        if velocities is not None:
            v = velocities.to(torch.float64)
            rng = rng + v[..., 0:1] * t
            azi = azi + v[..., 1:2] * t
        return torch.hypot(rng, azi)

    def differential_ranges(
        self, points: Tensor, *, velocities: Tensor | None = None, pulses: slice = slice(None)
    ) -> Tensor:
        """``dR`` of each point at pulses ``pulses``, float64 ``(..., m)``: what the data encode.

        Polar raster: ``x cos th_m + y sin th_m`` (stationary only). Track: exact range
        minus the range to the scene centre, the point at ``points + velocities * t_m``.

        Raises:
            OptionError: ``velocities`` on a polar raster (it has no slow time).
        """
        p = points.to(torch.float64)
        if self.track is None:
            if velocities is not None and bool(velocities.ne(0).any()):
                raise OptionError("moving scatterers need a track: the polar raster has no time")
            th = self.angles(device=p.device)[pulses]
            return p[..., 0:1] * th.cos() + p[..., 1:2] * th.sin()
        t = self.pulse_times(device=p.device)[pulses]
        centre = torch.zeros(1, 2, dtype=torch.float64, device=p.device)
        return self.slant_ranges(p, t, velocities) - self.slant_ranges(centre, t)

    def look_tangents(self, center: Tensor | tuple[float, float], times: Tensor) -> Tensor:
        """``tan`` of the look angle to ``center``: ``(x_c - V t) / (R0 + y_c)``, ``(..., M)``.

        ``center`` is one ``(range, cross-range)`` point or a ``(..., 2)`` tensor of them.
        Exactly linear in slow time on a straight track, which lets the polar-format azimuth
        transform be one chirp-z transform per range-frequency row (track only).
        """
        tr = self._track()
        t = times.to(torch.float64)
        c = torch.as_tensor(center, dtype=torch.float64, device=t.device)
        return (c[..., 1:2] - tr.platform_speed * t) / (tr.scene_range + c[..., 0:1])
