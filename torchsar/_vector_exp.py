"""numba: ``exp(x)`` for ``x <= 0`` without a library call, so that the loops of the
one-sweep filter kernels that evaluate it vectorise.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

from numba import njit, types
from numba.extending import intrinsic

from torchsar._block_sums import JIT

__all__ = ["exp_neg"]


_MAGIC = 6755399441055744.0  # 1.5 * 2^52: adding it rounds to an integer in the low bits
_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # ln 2 in two parts (Cody and Waite)
_LN2_LO = 1.90821492927058770002e-10


@intrinsic
def _bits(typingctx, value):
    """The IEEE bits of a float64 as an int64."""

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return types.int64(types.float64), codegen


@intrinsic
def _float(typingctx, bits):
    """The float64 whose IEEE bits are the int64 ``bits``."""

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return types.float64(types.int64), codegen


@njit(**JIT, inline="always")
def exp_neg(x):
    """``exp(x)`` for ``x <= 0`` (``-inf`` included), without a library call so that loops
    over it vectorise: ``x = k ln 2 + r``, ``|r| <= ln 2 / 2``, the Taylor polynomial of
    degree 13 in ``r`` (truncation below 1e-17) times ``2^k`` built from its bits. Results
    below the smallest normal double (``x < -708``) are 0."""
    xc = x if x > -708.0 else -708.0
    t = xc * _LOG2E + _MAGIC
    k = t - _MAGIC
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    p = 1.0 / 6227020800.0
    p = p * r + 1.0 / 479001600.0
    p = p * r + 1.0 / 39916800.0
    p = p * r + 1.0 / 3628800.0
    p = p * r + 1.0 / 362880.0
    p = p * r + 1.0 / 40320.0
    p = p * r + 1.0 / 5040.0
    p = p * r + 1.0 / 720.0
    p = p * r + 1.0 / 120.0
    p = p * r + 1.0 / 24.0
    p = p * r + 1.0 / 6.0
    p = p * r + 0.5
    p = p * r + 1.0
    p = p * r + 1.0
    v = p * _float((_bits(t) - _bits(_MAGIC) + 1023) << 52)
    return v if x > -708.0 else 0.0
