"""Exact order statistics over the CFAR training ring (the OS-CFAR clutter estimate).

:func:`ring_order_statistic` returns, for every pixel, the exact ``k``-th smallest value of
its training ring. On CPU with numba a compiled sliding rank bitset computes it
(:mod:`._kernels`); otherwise two exact torch algorithms (:mod:`.bisection` for small
rings, :mod:`.histogram` for large ones). All give the same values bit for bit.
"""

from torchsar.order_statistics.ring import ring_order_statistic

__all__ = ["ring_order_statistic"]
