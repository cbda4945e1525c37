"""Spotlight-mode acquisition geometry for deramped (polar-format) phase histories."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import OptionError, check_int, check_positive
from torchsar.imaging.items import check_device

__all__ = ["SPEED_OF_LIGHT", "SpotlightGeometry"]

SPEED_OF_LIGHT = 299_792_458.0  # m/s; the one definition (torchsar.motion imports it)


@dataclass(frozen=True)
class SpotlightGeometry:
    """Sampling of a deramped spotlight phase history (``(B, M pulses, K samples)``).

    Pulse ``m`` looks at azimuth ``th_m = (m - M//2) * aperture / M`` (radians) and sample
    ``k`` has frequency ``f_k = fc + (k - K//2) * bandwidth / K``, i.e. spatial wavenumber
    ``U_k = 4 pi f_k / c``. A scatterer at range ``x`` and cross-range ``y`` (metres, from
    the scene centre) contributes ``a * exp(-1j U_k (x cos th_m + y sin th_m))``.

    With these definitions the centred DFT pixel grid has ``range_pixel = c / (2 bandwidth)``
    and ``cross_range_pixel = c / (2 fc aperture)``: image rows are cross-range (pulses),
    columns range (frequencies). The polar raster is only approximately Cartesian, so FFT
    reconstruction of these data is an approximation (no inverse crime); the mismatch grows
    with scene size and fractional bandwidth.

    Attributes:
        center_frequency: carrier ``fc`` in Hz.
        bandwidth: swept bandwidth in Hz.
        aperture: total azimuth aperture in radians.
        pulses: number of pulses ``M``.
        samples: number of frequency samples ``K``.
        chirp_rate: sweep rate ``gamma`` of the transmitted chirp in Hz/s (instantaneous
            frequency ``f0 + gamma t``, i.e. ``exp(1j (w0 t + pi gamma t^2))``; the same unit
            as :class:`torchsar.motion.SpotlightParams`); used only for the residual video
            phase (RVP).

    Example:
        >>> geo = SpotlightGeometry.for_image((32, 32), pixel=1.0)
        >>> round(geo.range_pixel, 6), round(geo.cross_range_pixel, 6)
        (1.0, 1.0)
    """

    center_frequency: float
    bandwidth: float
    aperture: float
    pulses: int
    samples: int
    chirp_rate: float = 0.0

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

    @classmethod
    def for_image(
        cls,
        shape: tuple[int, int],
        *,
        pixel: float = 1.0,
        center_frequency: float = 10e9,
        chirp_rate: float = 0.0,
    ) -> SpotlightGeometry:
        """Geometry whose DFT pixel grid is ``shape`` = ``(M, K)`` with square ``pixel`` (m)."""
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

    @property
    def range_pixel(self) -> float:
        """Range pixel spacing ``c / (2 bandwidth)`` in metres (image columns)."""
        return SPEED_OF_LIGHT / (2 * self.bandwidth)

    @property
    def cross_range_pixel(self) -> float:
        """Cross-range pixel spacing ``c / (2 fc aperture)`` in metres (image rows)."""
        return SPEED_OF_LIGHT / (2 * self.center_frequency * self.aperture)

    def wavenumbers(self, *, dtype: torch.dtype = torch.float64, device=None) -> Tensor:
        """``U_k = 4 pi f_k / c`` for the ``K`` samples, shape ``(K,)``."""
        k = torch.arange(self.samples, dtype=dtype, device=check_device(device)) - self.samples // 2
        freq = self.center_frequency + k * (self.bandwidth / self.samples)
        return 4 * math.pi * freq / SPEED_OF_LIGHT

    def angles(self, *, dtype: torch.dtype = torch.float64, device=None) -> Tensor:
        """Pulse azimuths ``th_m`` in radians, shape ``(M,)``."""
        m = torch.arange(self.pulses, dtype=dtype, device=check_device(device)) - self.pulses // 2
        return m * (self.aperture / self.pulses)

    def pixel_positions(
        self, shape: tuple[int, int], *, dtype: torch.dtype = torch.float64, device=None
    ) -> tuple[Tensor, Tensor]:
        """Cross-range ``y`` (rows, ``(H,)``) and range ``x`` (columns, ``(W,)``) in metres."""
        h, w = shape
        y = (torch.arange(h, dtype=dtype, device=device) - h // 2) * self.cross_range_pixel
        x = (torch.arange(w, dtype=dtype, device=device) - w // 2) * self.range_pixel
        return y, x
