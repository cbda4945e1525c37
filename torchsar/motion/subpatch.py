"""Subpatch images: one full image per subpatch centre (the seed's Figure 1 layout)."""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar._checks import check_int
from torchsar.errors import OptionError
from torchsar.motion.formation import polar_format
from torchsar.motion.params import SpotlightParams

__all__ = ["subpatch_centers", "subpatch_images"]


def subpatch_centers(
    params: SpotlightParams, grid: tuple[int, int] = (2, 2), *, dtype: torch.dtype = torch.float64
) -> Tensor:
    """Centres of a ``grid = (rows, cols)`` tiling of the scene, ``(P, 2)`` ``(range, azimuth)`` m.

    Row-major order (``p = row * cols + col``), rows from near to far range, columns from
    early to late azimuth. The default 2x2 tiling of a 200 m scene gives ``(+-50, +-50)``.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> subpatch_centers(SpotlightParams.from_system()).tolist()
        [[-50.0, -50.0], [-50.0, 50.0], [50.0, -50.0], [50.0, 50.0]]
    """
    if not (isinstance(grid, tuple | list) and len(grid) == 2):
        raise OptionError(f"grid must be (rows, cols), got {grid!r}")
    gy, gx = (check_int(v, f"grid[{i}]", minimum=1) for i, v in enumerate(grid))
    ey, ex = params.scene_extent
    ys = (torch.arange(gy, dtype=dtype) + 0.5) * ey / gy - ey / 2
    xs = (torch.arange(gx, dtype=dtype) + 0.5) * ex / gx - ex / 2
    return torch.cartesian_prod(ys, xs)


def subpatch_images(
    phase_history: Tensor,
    params: SpotlightParams,
    *,
    grid: tuple[int, int] = (2, 2),
    size: tuple[int, int] | None = None,
    window: str = "hann",
) -> Tensor:
    """Form one complex image per subpatch centre, each referenced to (centred on) its centre.

    Every image covers the full image extent around its own centre, so a stationary target
    at scene position ``s`` appears at ``s - c_p`` in image ``p``: the displacement between
    subpatch images is the same for every stationary target (up to wavefront-curvature
    distortion), while a mover's differs.

    Args:
        phase_history: complex ``(B, M, K)`` deramped on the scene centre.
        params: the system.
        grid: ``(rows, cols)`` subpatch tiling; ``P = rows * cols`` images.
        size: ``(H, W)`` pixels per image; default ``params.image_size``.
        window: k-space taper (see :func:`~torchsar.motion.formation.polar_format`).

    Returns:
        complex ``(B, P, H, W)``; channel ``p`` is centred on ``subpatch_centers(params, grid)[p]``.

    Raises:
        InputTypeError, ShapeError, OptionError: bad input.

    Shape:
        ``(B, M, K)`` -> ``(B, P, H, W)``.

    References:
        M. Kartal, S. Paker, S. Kent, "A new subpatch focusing algorithm for spotlight SAR
        processing of large scenes", EUSAR 2010.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> from torchsar.sar import simulate_phase_history
        >>> p = SpotlightParams.from_system(azimuth_resolution=1.0, image_size=(32, 32))
        >>> g = simulate_phase_history(torch.zeros(2, 1, 2), p.geometry)
        >>> subpatch_images(g, p).shape
        torch.Size([2, 4, 32, 32])
    """
    centers = subpatch_centers(params, grid)
    images = [
        polar_format(
            phase_history, params, center=(float(c[0]), float(c[1])), size=size, window=window
        )
        for c in centers
    ]
    return torch.stack(images, dim=1)
