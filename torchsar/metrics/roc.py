"""Scale-free pixel ROC: exact counts per key of the detector statistic, additive across
batches and shards.

No threshold grid is fixed in advance and no value is clipped: every pixel's statistic is
counted under its *key*, an order-preserving integer of its float64 value (float32 and other
float statistics are converted exactly):

- ``-0.0`` becomes ``+0.0``; the 64 IEEE bits as a signed integer, with every bit but the
  sign flipped for a negative value, order like the floats themselves; the key keeps their
  top 17 bits (the sign, the 11 exponent bits and the top 5 mantissa bits,
  :data:`MANTISSA_BITS`).
- Every finite float64 and ``±inf`` has a key, and keys are monotone non-decreasing in the
  value.
- Resolution: the values of one key span a relative width of at most ``2**-5`` (3.1 %):
  ``(largest - smallest) / |smallest| < 2**-5`` for every ``|x| >= 2**-1022`` (the normal
  float64 range, which holds every nonzero float32); below it the keys have the absolute
  width ``2**-1027`` (``largest - smallest < 2**-1027``; ``0`` shares its key with the
  positive float64 values under it).

The state holds, for each key present, its target and clutter pixels, and the totals of
target and clutter pixels; :meth:`RocAccumulator.pixel_curve` gives ``Pd`` and ``Pfa`` for
``statistic > t`` exactly at each key's largest value ``t``. States of any split of a dataset
add up with ``+`` to the state of one pass, in any order. (Object-level curves come from
:class:`~torchsar.metrics.ObjectState`: objects ranked by score, not images re-labelled per
threshold.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from torchsar import _jit
from torchsar._checks import check_same_shape, has_nan
from torchsar.errors import InputTypeError, InputValueError
from torchsar.metrics.counts import PixelCounts, pixel_counts

__all__ = ["RocAccumulator", "key_thresholds", "pixel_keys"]


_NAN = "statistic must not contain NaN (it has no place on a ROC)"
MANTISSA_BITS = 5
"""The mantissa bits a key keeps after the sign and the 11 exponent bits: one key spans a
relative width of at most ``2**-MANTISSA_BITS``. :mod:`torchsar.metrics._kernels` defines
the same number (it must not import it from here: numba's cache would keep the old value)."""
_SHIFT = 64 - 12 - MANTISSA_BITS  # the bits below the key
_LOW63 = (1 << 63) - 1  # every bit but the sign
_SIGN = np.int64(-(1 << 63))  # the sign bit alone
_INF_KEY = 2047 << MANTISSA_BITS  # +inf's key (exponent all ones, mantissa 0); -inf's: ~it

_Sparse = tuple[np.ndarray, np.ndarray, np.ndarray]
"""Sorted unique int32 keys with their int64 target and clutter counts."""


def pixel_keys(x: Tensor) -> Tensor:
    """The int64 key of each value of ``x`` (any float tensor, free of NaN): the top 17 bits
    of the order-preserving integer of its float64 value, ``-0.0`` as ``+0.0``.

    Examples:
        >>> pixel_keys(torch.tensor([-1.0, -0.0, 0.0, 1.0, 1.03, 1.04, torch.inf])).tolist()
        [-32737, 0, 0, 32736, 32736, 32737, 65504]
    """
    b = (x.to(torch.float64) + 0.0).view(torch.int64)  # + 0.0: -0.0 becomes +0.0
    return (b ^ ((b >> 63) & _LOW63)) >> _SHIFT


def key_thresholds(keys: np.ndarray) -> np.ndarray:
    """The largest float64 of each key (``x > t`` exactly when ``x``'s key is above ``t``'s):
    ``+inf`` for the key of ``+inf``.

    Examples:
        >>> key_thresholds(pixel_keys(torch.tensor([-1.0, 0.0, 1.0])).numpy()).tolist()
        [-1.0, 6.95335580783495e-310, 1.0312499999999998]
    """
    k = np.asarray(keys, dtype=np.int64)
    up = ((k + 1) << _SHIFT) - 1  # a non-negative key: its top bit pattern
    down = np.maximum(~k << _SHIFT, 1) | _SIGN  # a negative key: its smallest magnitude
    t = np.where(k >= 0, up, down).view(np.float64)
    return np.where(k == _INF_KEY, np.inf, t)


def _no_keys() -> np.ndarray:
    return np.zeros(0, np.int32)


def _no_counts() -> np.ndarray:
    return np.zeros(0, np.int64)


def _flat(t: Tensor) -> np.ndarray:
    """A CPU tensor as a flat contiguous array (no copy when it is contiguous)."""
    return t.contiguous().view(-1).numpy()


def _sparse(row_keys: np.ndarray, table: np.ndarray) -> _Sparse:
    """The keys present in an ``(n, 2)`` table of (target, clutter) counts whose row ``j``
    counts the key ``row_keys[j]``, with their counts."""
    rows = np.flatnonzero(table[:, 0] | table[:, 1])
    return row_keys[rows].astype(np.int32), table[rows, 0].copy(), table[rows, 1].copy()


def _merge(a: _Sparse, b: _Sparse) -> _Sparse:
    """The union of two sparse counts, the counts of a key in both summed (new arrays)."""
    (keys, t, c), (kb, tb, cb) = a, b
    at = np.searchsorted(keys, kb)
    new = keys[np.minimum(at, keys.size - 1)] != kb if keys.size else np.ones(kb.size, bool)
    if new.any():  # keys of b not in a: inserted in order
        keys, t, c = (np.insert(v, at[new], w) for v, w in ((keys, kb[new]), (t, 0), (c, 0)))
        at = np.searchsorted(keys, kb)
    else:
        t, c = t.copy(), c.copy()
    t[at] += tb
    c[at] += cb
    return keys, t, c


@dataclass(eq=False)
class RocAccumulator:
    """Accumulates the pixel ROC counts of one detector on one dataset, scale-free.

    Each pixel not ignored counts under the key of its statistic (see the module: the top 17
    bits of the order-preserving integer of its float64 value; the values of one key span a
    relative width of at most ``2**-5``, 3.1 %, for every ``|x| >= 2**-1022``, every nonzero
    float32 included, and an absolute width of ``2**-1027`` below). Nothing is clipped: every
    finite value and ``+inf`` has its own key; a pixel at ``-inf`` exceeds no threshold of
    the curve and counts in the totals only. States of any split of a dataset, added with
    ``+`` in any order, equal the state of one pass.

    Attributes:
        keys: sorted int32 keys present.
        target_counts: int64 target pixels of each key.
        clutter_counts: int64 clutter pixels of each key.
        targets: target pixels counted.
        clutter: clutter pixels counted.

    Examples:
        >>> a, b = RocAccumulator(), RocAccumulator()
        >>> tgt = torch.tensor([True, False, False])
        >>> _ = a.update(torch.tensor([3.0, 1e300, -2.0]), tgt)
        >>> _ = b.update(torch.tensor([3.0, 0.5, 0.5]), tgt)
        >>> c = (a + b).pixel_curve()
        >>> c["pd_pixel"].tolist(), c["pfa_pixel"].tolist()
        ([1.0, 1.0, 1.0, 0.0, 0.0], [1.0, 0.75, 0.25, 0.25, 0.0])
    """

    keys: np.ndarray = field(init=False, default_factory=_no_keys)
    target_counts: np.ndarray = field(init=False, default_factory=_no_counts)
    clutter_counts: np.ndarray = field(init=False, default_factory=_no_counts)
    targets: int = field(init=False, default=0)
    clutter: int = field(init=False, default=0)

    def update(
        self,
        statistic: Tensor,
        target: Tensor,
        ignore: Tensor | None = None,
        *,
        detected: Tensor | None = None,
    ) -> PixelCounts | None:
        """Add a batch: ``statistic`` float, ``target`` bool, optional ``ignore`` bool, all
        of one shape. With ``detected`` (a bool detection mask of that shape) also returns
        its :func:`~torchsar.metrics.pixel_counts` against ``target`` and ``ignore``, counted
        in the same compiled call where the kernels run (float32 or float64 on the CPU).

        Examples:
            >>> acc = RocAccumulator()
            >>> stat = torch.tensor([0.5, 2.0, 3.0]); tgt = torch.tensor([False, True, False])
            >>> c = acc.update(stat, tgt, detected=stat > 1.0)
            >>> (c.tp, c.fp, c.targets, c.clutter), acc.targets
            ((1, 1, 1, 2), 1)
        """
        if not isinstance(statistic, Tensor) or not statistic.is_floating_point():
            raise InputTypeError("statistic must be a floating torch.Tensor")
        for name, t in (("target", target), ("ignore", ignore), ("detected", detected)):
            if t is not None and (not isinstance(t, Tensor) or t.dtype != torch.bool):
                raise InputTypeError(f"{name} must be a bool tensor")
            if t is not None:
                check_same_shape(statistic, t, "statistic", name)
        batch, counts = _count(statistic, target, ignore, detected)
        self._add(batch, counts.targets, counts.clutter)
        return None if detected is None else counts

    def update_sparse(
        self, values: Tensor, target: Tensor, ignore: Tensor, targets: int, clutter: int
    ) -> None:
        """Add a batch whose statistic is ``-inf`` except at some pixels: their ``values``
        with their ``target`` / ``ignore`` flags (bool, same length), and the batch's
        counts of target and clutter pixels (``-inf`` exceeds no threshold, so only the
        listed pixels reach the per-key counts). Equal to :meth:`update` on the dense batch.

        Examples:
            >>> a, b = RocAccumulator(), RocAccumulator()
            >>> stat = torch.full((6,), -torch.inf); stat[[1, 4]] = torch.tensor([2.0, 0.5])
            >>> tgt = torch.tensor([0, 1, 1, 0, 0, 0], dtype=torch.bool)
            >>> a.update(stat, tgt)
            >>> no = torch.zeros(2, dtype=torch.bool)
            >>> b.update_sparse(stat[[1, 4]], tgt[[1, 4]], no, targets=2, clutter=4)
            >>> a == b
            True
        """
        batch, _ = _count(values, target, ignore, None)
        self._add(batch, int(targets), int(clutter))

    def _sparse(self) -> _Sparse:
        return self.keys, self.target_counts, self.clutter_counts

    def _add(self, batch: _Sparse, targets: int, clutter: int) -> None:
        self.keys, self.target_counts, self.clutter_counts = _merge(self._sparse(), batch)
        self.targets += targets
        self.clutter += clutter

    def __add__(self, other: RocAccumulator) -> RocAccumulator:
        out = RocAccumulator()
        for acc in (self, other):
            out._add(acc._sparse(), acc.targets, acc.clutter)
        return out

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RocAccumulator):
            return NotImplemented
        arrays = ("keys", "target_counts", "clutter_counts")
        return (self.targets, self.clutter) == (other.targets, other.clutter) and all(
            np.array_equal(getattr(self, k), getattr(other, k)) for k in arrays
        )

    def __getstate__(self) -> dict:
        """The state as data: the keys, the counts and the two totals."""
        return {
            k: getattr(self, k)
            for k in ("keys", "target_counts", "clutter_counts", "targets", "clutter")
        }

    def __setstate__(self, state: dict) -> None:
        """Rebuild from saved data (a state file, a pickle), checked: a state of another
        layout (a threshold grid's, from an older version) raises ``ValueError``."""
        if set(state) != {"keys", "target_counts", "clutter_counts", "targets", "clutter"}:
            raise ValueError(f"not a RocAccumulator state (fields {sorted(state)})")
        if not _well_formed(state["keys"], state["target_counts"], state["clutter_counts"]):
            raise ValueError("not a RocAccumulator state (keys and counts)")
        self.__dict__.update(state)

    @property
    def target_hits(self) -> Tensor:
        """Target pixels above each threshold of :meth:`pixel_curve` (int64)."""
        return torch.from_numpy(_exceeding(self.target_counts))

    @property
    def clutter_hits(self) -> Tensor:
        """Clutter pixels above each threshold of :meth:`pixel_curve` (int64)."""
        return torch.from_numpy(_exceeding(self.clutter_counts))

    def pixel_curve(self) -> dict[str, np.ndarray]:
        """``threshold``, ``pd_pixel``, ``pfa_pixel`` arrays, ascending in ``threshold``:
        first ``-inf`` (every pixel above ``-inf``), then the largest float64 of each key
        present, so that ``pd_pixel[i]`` is exactly the fraction of target pixels with
        ``statistic > threshold[i]`` (``pfa_pixel`` of clutter pixels; a fraction of 0
        pixels is 0).

        Examples:
            >>> acc = RocAccumulator()
            >>> _ = acc.update(torch.tensor([0.5, 2.0, 3.0]), torch.tensor([False, True, False]))
            >>> c = acc.pixel_curve()
            >>> float(c["threshold"][0]), c["pd_pixel"].tolist(), c["pfa_pixel"].tolist()
            (-inf, [1.0, 1.0, 0.0, 0.0], [1.0, 0.5, 0.5, 0.0])
        """
        threshold = np.concatenate([[-np.inf], key_thresholds(self.keys)])
        return {
            "threshold": threshold,
            "pd_pixel": _exceeding(self.target_counts) / max(self.targets, 1),
            "pfa_pixel": _exceeding(self.clutter_counts) / max(self.clutter, 1),
        }


def _well_formed(keys: object, t: object, c: object) -> bool:
    """Whether these are sorted unique int32 keys with int64 counts of each."""
    if not all(isinstance(a, np.ndarray) and a.ndim == 1 for a in (keys, t, c)):
        return False
    types = keys.dtype == np.int32 and t.dtype == c.dtype == np.int64
    return types and keys.shape == t.shape == c.shape and bool(np.all(np.diff(keys) > 0))


def _exceeding(counts: np.ndarray) -> np.ndarray:
    """Pixels above ``-inf``, then above each key: ``[sum, sum - cumsum]``."""
    total = int(counts.sum())
    return np.concatenate([[total], total - np.cumsum(counts)]).astype(np.int64)


def _count(
    values: Tensor, target: Tensor, ignore: Tensor | None, detected: Tensor | None
) -> tuple[_Sparse, PixelCounts]:
    """The per-key counts of a batch and the pixel counts of ``detected`` (``tp``, ``fp``
    0 without one); raises on NaN before anything is added. One compiled call
    (:mod:`torchsar.metrics._kernels`) where the kernels take ``values``, else tensor code
    with the same counts."""
    if _jit.for_tensor(values.detach()):
        return _compiled_count(values, target, ignore, detected)
    if has_nan(values):
        raise InputValueError(_NAN)
    if ignore is not None:
        ignore = ignore.to(values.device)
    target = target.to(values.device)
    if detected is None:
        care = target.numel() if ignore is None else int(torch.count_nonzero(~ignore))
        tgt = target if ignore is None else target & ~ignore
        n_target = int(torch.count_nonzero(tgt))
        counts = PixelCounts(0, 0, n_target, care - n_target)
    else:
        counts = pixel_counts(detected, target, ignore=ignore)
    return _tensor_keys(values.detach(), target, ignore), counts


def _tensor_keys(values: Tensor, target: Tensor, ignore: Tensor | None) -> _Sparse:
    """The per-key counts of a batch in tensor code (any device): a bincount over (key from
    the first above ``-inf``'s, class), ``-inf`` in row 0 and ignored pixels as a third
    class, both left out."""
    hi = values.max() if values.numel() else None
    if hi is None or bool(hi == -torch.inf):
        return _no_keys(), _no_counts(), _no_counts()
    lo = values.masked_fill(values == -torch.inf, torch.inf).min()
    kmin, kmax = (int(k) for k in pixel_keys(torch.stack([lo, hi])))
    n = kmax - kmin + 2  # row 0: -inf
    cls = (~target).long()
    if ignore is not None:
        cls.masked_fill_(ignore, 2)
    index = pixel_keys(values).sub_(kmin - 1).clamp_(min=0).mul_(3).add_(cls)
    table = torch.bincount(index.view(-1), minlength=3 * n).view(n, 3)[1:, :2]
    return _sparse(np.arange(kmin, kmin + n - 1), table.cpu().numpy())


def _compiled_count(
    values: Tensor, target: Tensor, ignore: Tensor | None, detected: Tensor | None
) -> tuple[_Sparse, PixelCounts]:
    """:func:`torchsar.metrics._kernels.roc_pass` on a CPU batch: one compiled call."""
    from torchsar.metrics import _kernels

    flat = _flat(values.detach())
    lo, hi = _finite_range(flat)
    tgt = _flat(target)
    ign = tgt if ignore is None else _flat(ignore)
    det = tgt if detected is None else _flat(detected)
    row_keys, table, tp, det_n = _kernels.roc_pass(
        flat, lo, hi, tgt, ign, ignore is not None, det, detected is not None
    )
    n_target, n_clutter = (int(v) for v in table.sum(0))
    keys, t, c = _sparse(row_keys, table[:-2])
    if table[-2].any():  # +inf: the last key
        keys = np.append(keys, np.int32(_INF_KEY))
        t, c = np.append(t, table[-2, 0]), np.append(c, table[-2, 1])
    return (keys, t, c), PixelCounts(int(tp), int(det_n - tp), n_target, n_clutter)


def _finite_range(flat: np.ndarray) -> tuple[float, float]:
    """The smallest and largest finite value of ``flat`` (``inf, -inf`` for none); raises
    on NaN."""
    from torchsar.metrics import _kernels

    if flat.size == 0:
        return np.inf, -np.inf
    lo, hi = float(flat.min()), float(flat.max())  # NaN when a value is
    if np.isnan(lo) or np.isnan(hi):
        raise InputValueError(_NAN)
    if np.isinf(lo) or np.isinf(hi):
        lo, hi = (float(v) for v in _kernels.finite_range(flat))
    return lo, hi
