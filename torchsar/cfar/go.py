"""Greatest-of CFAR on the 4 pinwheel blocks."""

from __future__ import annotations

from torch import Tensor

from torchsar.cfar.blocks import block_cfar, block_threshold
from torchsar.detection import WINDOW, Detection, DetectorSpec

__all__ = ["go", "go_threshold"]


def go(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    valid: Tensor | None = None,
) -> Detection:
    """Greatest-of CFAR: statistic ``I / max_j(mean_j)`` over the 4 pinwheel blocks.

    The blocks (top, right, bottom, left; ``t x (2g+t+1)`` cells each, see
    :func:`~torchsar.windows.pinwheel_rects`) tile the training ring. The threshold factor is
    exact for exponential clutter: ``pfa = E[exp(-alpha max_j mean_j)]`` integrated over the
    law of the maximum of the block means and solved for ``alpha``
    (:func:`~torchsar.cfar.thresholds.block_factor`, cached per block sizes and ``pfa``).
    GO holds the false-alarm rate at clutter edges at the price of masking close targets.

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
        Hansen, V. G., Sawyers, J. H., IEEE TAES 16(5), 648-650, 1980,
        doi:10.1109/TAES.1980.308989.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> go(x, guard=1, train=2).mask.sum().item()
        1
    """
    return block_cfar(x, guard, train, pfa, valid, "max")


def go_threshold(*, guard: int, train: int, pfa: float) -> float:
    """The design threshold of :func:`go` for these options (no image needed)."""
    return block_threshold(guard, train, pfa, "max")


SPEC = DetectorSpec(name="go", detect=go, order=2, options=WINDOW, threshold=go_threshold)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
