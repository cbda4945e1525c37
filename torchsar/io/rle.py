"""COCO run-length encodings (RLE) decoded straight to pixel lists, many at once.

A COCO mask is a list of run lengths over the pixels in column-major order, zeros first;
the compressed form writes each count in 5-bit groups as characters (offset 48, bit 0x20:
another group follows, bit 0x10 of the last group: negative) and, from the fourth count on,
as the difference to the count two places before (see ``pycocotools``' ``maskApi.c``,
``rleFrString``). Decoding to a dense ``(H, W)`` mask per detection costs ``H * W`` per
mask; this decodes every string of a batch with a few vectorised passes over the
characters and writes only the pixels that are set.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["check_strings", "counts_from_strings", "rle_pixels"]


def _segment_starts(ids: np.ndarray) -> np.ndarray:
    """Index of the first element of each element's run of equal ``ids`` (sorted)."""
    return np.searchsorted(ids, ids, side="left")


def counts_from_strings(strings: Sequence[bytes | str]) -> tuple[np.ndarray, np.ndarray]:
    """The run lengths of compressed COCO RLE strings: ``(counts, owner)``, the counts of
    every string concatenated and the string index of each.

    Examples:
        >>> from pycocotools import mask as mask_utils
        >>> m = np.zeros((4, 3), np.uint8, order="F"); m[1:3, 1] = 1
        >>> s = mask_utils.encode(m)["counts"]
        >>> counts_from_strings([s])[0].tolist()  # 5 zeros, 2 ones, 5 zeros (column-major)
        [5, 2, 5]
    """
    raw = [s.encode() if isinstance(s, str) else bytes(s) for s in strings]
    if not raw or not any(raw):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    c = np.frombuffer(b"".join(raw), np.uint8).astype(np.int64) - 48
    end = (c & 0x20) == 0  # the last 5-bit group of a count
    value = np.concatenate([[0], np.cumsum(end)[:-1]])  # the count each group belongs to
    k = np.arange(c.size) - _segment_starts(value)  # its group number within the count
    x = np.add.reduceat((c & 0x1F) << (5 * k), np.flatnonzero(k == 0))
    last = np.flatnonzero(end)
    negative = (c[last] & 0x10) != 0
    x[negative] -= np.int64(1) << (5 * (k[last][negative] + 1))
    chars = np.array([len(s) for s in raw])
    owner = np.repeat(np.arange(len(raw)), chars)[last]  # the string of each count
    m = np.arange(x.size) - _segment_starts(owner)  # position of the count in its string
    chain = np.where(m == 0, 0, 1 + m % 2)  # counts 1, 3, 5 ... and 2, 4, 6 ... are deltas
    key = owner * 3 + chain
    order = np.argsort(key, kind="stable")
    summed = np.cumsum(x[order])
    first = _segment_starts(key[order])
    before = np.where(first > 0, summed[np.maximum(first - 1, 0)], 0)
    counts = np.empty_like(x)
    counts[order] = summed - before
    counts[m == 0] = x[m == 0]
    return counts, owner


def rle_pixels(
    counts: np.ndarray, owner: np.ndarray, n: int, shape: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels set by RLE run lengths: ``(mask index, flat row-major index)`` for ``n``
    masks of ``shape`` (run lengths ``counts`` of mask ``owner``, in order, zeros first).

    Examples:
        >>> rle_pixels(np.array([5, 2, 5]), np.array([0, 0, 0]), 1, (4, 3))[1].tolist()
        [4, 7]
    """
    h, w = shape
    if counts.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    m = np.arange(counts.size) - _segment_starts(owner)
    within = np.cumsum(counts)
    first = _segment_starts(owner)
    start = within - counts - np.where(first > 0, within[np.maximum(first - 1, 0)], 0)
    ones = np.flatnonzero((m % 2 == 1) & (counts > 0))
    length = counts[ones]
    total = int(length.sum())
    base = np.repeat(start[ones] - np.concatenate([[0], np.cumsum(length)[:-1]]), length)
    p = base + np.arange(total)  # column-major position within its mask
    col, row = np.divmod(p, h)
    return np.repeat(owner[ones], length), row * w + col


def _allowed_span(total: int) -> int:
    """The most characters one run length of a ``total``-pixel mask can need (5 bits a
    character, a sign, one to spare), at most 12 (60 bits: no overflow)."""
    return min(12, -(-(int(total).bit_length() + 1) // 5) + 1)


def check_strings(
    strings: Sequence[bytes | str], totals: Sequence[int]
) -> tuple[list[str | None], np.ndarray, np.ndarray]:
    """Check compressed COCO RLE strings before decoding them, all in a few vectorised
    passes: ``(problems, sums, minima)``. ``problems[i]`` says what keeps string ``i`` from
    decoding (a character that is no code, ``'0'`` to ``'o'``; an end inside a run length;
    a run length longer than a mask of ``totals[i]`` pixels needs) or is ``None``; then
    ``sums[i]`` and ``minima[i]`` are the sum and the least of its run lengths (``0`` for
    an empty string), for the caller to compare with ``totals[i]`` and zero.

    Examples:
        >>> problems, sums, minima = check_strings(["52", "5~", "PPo"], [7, 7, 7])
        >>> problems[0], int(sums[0]), int(minima[0])
        (None, 7, 2)
        >>> problems[1:]
        ["character '~' at 1 is not a code ('0' to 'o')", 'it ends inside a run length']
    """
    n = len(strings)
    problems: list[str | None] = [None] * n
    raw: list[bytes] = []
    for i, s in enumerate(strings):
        try:
            raw.append(s.encode("ascii") if isinstance(s, str) else bytes(s))
        except UnicodeEncodeError:
            raw.append(b"")
            problems[i] = "it holds characters outside ASCII"
    sums, minima = np.zeros(n, np.int64), np.zeros(n, np.int64)
    lengths = np.array([len(r) for r in raw], np.int64)
    c = np.frombuffer(b"".join(raw), np.uint8).astype(np.int64) - 48
    starts = np.cumsum(lengths) - lengths
    bad = np.flatnonzero((c < 0) | (c > 63))
    if bad.size:
        owner = np.searchsorted(starts, bad, side="right") - 1
        strings_hit, first = np.unique(owner, return_index=True)
        for i, at in zip(
            strings_hit.tolist(), (bad[first] - starts[strings_hit]).tolist(), strict=True
        ):
            char = chr(raw[i][at])
            problems[i] = f"character {char!r} at {at} is not a code ('0' to 'o')"
    for i in np.flatnonzero(lengths > 0).tolist():
        if problems[i] is None and c[starts[i] + lengths[i] - 1] & 0x20:
            problems[i] = "it ends inside a run length"
    keep = [i for i in range(n) if problems[i] is None and lengths[i]]
    if not keep:
        return problems, sums, minima
    cc = np.concatenate([c[starts[i] : starts[i] + lengths[i]] for i in keep])
    end = (cc & 0x20) == 0
    group = np.concatenate([[0], np.cumsum(end)[:-1]])  # the run length of each character
    span = np.bincount(group)  # characters of each run length
    owner = np.repeat(np.arange(len(keep)), lengths[keep])[end]  # of each run length
    longest = np.zeros(len(keep), np.int64)
    np.maximum.at(longest, owner, span)
    decodable = []
    for j, i in enumerate(keep):
        allowed = _allowed_span(totals[i])
        if longest[j] > allowed:
            problems[i] = (
                f"a run length spans {longest[j]} characters, more than the "
                f"{allowed} a mask of {totals[i]} pixels needs"
            )
        else:
            decodable.append(i)
    if decodable:
        counts, owner = counts_from_strings([raw[i] for i in decodable])
        got_sum = np.zeros(len(decodable), np.int64)
        got_min = np.full(len(decodable), np.iinfo(np.int64).max)
        np.add.at(got_sum, owner, counts)
        np.minimum.at(got_min, owner, counts)
        sums[decodable], minima[decodable] = got_sum, got_min
    return problems, sums, minima
