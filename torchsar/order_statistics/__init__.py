"""Exact order statistics over the CFAR training ring (the OS-CFAR clutter estimate).

:func:`ring_order_statistic` returns, for every pixel, the exact ``k``-th smallest value of
its training ring. Two exact algorithms compute it (:mod:`.bisection` for small rings,
:mod:`.histogram` for large ones); both give the same values bit for bit.
"""

from torchsar.order_statistics.ring import ring_order_statistic

__all__ = ["ring_order_statistic"]
