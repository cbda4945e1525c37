"""Smallest-of CFAR on the 4 pinwheel blocks."""

from __future__ import annotations

from torch import Tensor

from torchsar.cfar.blocks import block_cfar, block_threshold
from torchsar.detection import WINDOW, Detection, DetectorSpec

__all__ = ["so", "so_threshold"]


def so(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    valid: Tensor | None = None,
) -> Detection:
    """Smallest-of CFAR: statistic ``I / min_j(mean_j)`` over the 4 pinwheel blocks.

    The blocks (top, right, bottom, left; ``t x (2g+t+1)`` cells each, see
    :func:`~torchsar.windows.pinwheel_rects`) tile the training ring. The threshold factor is
    exact for exponential clutter: ``pfa = E[exp(-alpha min_j mean_j)]`` integrated over the
    law of the minimum of the block means and solved for ``alpha``
    (:func:`~torchsar.cfar.thresholds.block_factor`, cached per block sizes and ``pfa``).
    SO resolves closely spaced targets (one block free of the interferer is enough) at the
    price of false alarms at clutter edges.

    Border rule: blocks lose their out-of-image (and invalid) cells; a pixel whose block sizes
    differ from the interior ones has its statistic rescaled by
    ``alpha(interior) / alpha(its sizes)`` (exact factor for its own sizes; empty blocks are
    left out), so one global threshold keeps the design ``pfa`` everywhere.

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g.
        train: training-band width t.
        pfa: design probability of false alarm.
        valid: optional bool mask of usable cells.

    Returns:
        :class:`Detection` with ``threshold = alpha`` of the interior block sizes.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Trunk, G. V., IEEE TAES 14(5), 750-755, 1978, doi:10.1109/TAES.1978.308625.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> so(x, guard=1, train=2).mask.sum().item()
        1
    """
    return block_cfar(x, guard, train, pfa, valid, "min")


def so_threshold(*, guard: int, train: int, pfa: float) -> float:
    """The design threshold of :func:`so` for these options (no image needed)."""
    return block_threshold(guard, train, pfa, "min")


SPEC = DetectorSpec(name="so", detect=so, order=3, options=WINDOW, threshold=so_threshold)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
