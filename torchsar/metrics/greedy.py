"""COCO's greedy one-to-one matching (``pycocotools``' ``evaluateImg``) of many problems at
once, from the quality of every candidate pair.

A *problem* is one image (class-agnostic) or one (image, class) pair. Its detections are
visited in descending score order (ties: the order given); each takes, among the instances
it reaches (quality at least ``min(t, 1 - 1e-10)``) and not yet taken, the one of highest
quality (ties: the later one), the instances that count before the ignored ones (an ignored
instance, crowd or outside an area range, is only taken when no counted one is reached); a
crowd instance can be taken again and again. A detection that takes an ignored instance is
ignored. Everything is vectorised over problems, area ranges and thresholds, one detection
rank at a time.

:func:`assign_pairs` is the entry point: it takes the candidate pairs of every problem as flat
arrays (detections and instances numbered by problem), pads problems of similar size into
blocks and returns, per detection, area range and threshold, the instance it took.
"""

from __future__ import annotations

import numpy as np

__all__ = ["WORK", "assign_pairs", "greedy_assign"]

WORK = 1 << 22
"""Elements of the matcher's arrays per block of problems."""


def _row_ranks(q: np.ndarray) -> np.ndarray:
    """Rank of each entry within its last-axis row, ascending by value then by position.

    Example:
        >>> _row_ranks(np.array([[0.5, 0.2, 0.5]])).tolist()
        [[1, 0, 2]]
    """
    order = np.argsort(q, axis=-1, kind="stable")
    rank = np.empty(q.shape, np.int16 if 2 * q.shape[-1] < 2**15 else np.int32)
    np.put_along_axis(rank, order, np.arange(q.shape[-1], dtype=rank.dtype), axis=-1)
    return rank


def greedy_assign(
    quality: np.ndarray, ignore: np.ndarray, crowd: np.ndarray, n_det: np.ndarray, thresholds
) -> np.ndarray:
    """The greedy matching (see the module docstring) of padded problems.

    Args:
        quality: ``(P, D, G)`` pair quality (IoU), ``-inf`` for padding.
        ignore: ``(P, A, G)`` ignored instances per area range (crowd, outside the range,
            padding).
        crowd: ``(P, G)`` crowd instances (taken any number of times).
        n_det: ``(P,)`` detections of each problem, non-increasing (rows past it: padding).
        thresholds: ``(T,)`` minimum quality.

    Returns:
        int ``(P, D, A, T)``: the instance column each detection took, -1 none.

    Example:
        >>> q = np.array([[[0.6, 0.6], [0.7, 0.0]]])  # two detections, two instances
        >>> greedy_assign(q, np.zeros((1, 1, 2), bool), np.zeros((1, 2), bool),
        ...               np.array([2]), [0.5, 0.65])[0, :, 0].tolist()
        [[1, -1], [0, 0]]
    """
    P, D, G = quality.shape
    A, thr = ignore.shape[1], np.minimum(np.asarray(thresholds, np.float64), 1 - 1e-10)
    out = np.full((P, D, A, thr.size), -1, np.int32)
    if P == 0 or D == 0 or G == 0:
        return out
    rank = _row_ranks(quality)
    # instances first (G, P, ...) so that every step is elementwise over whole arrays; the key
    # 1 + group * G + rank (0: not a candidate) is largest for pycocotools' choice and unique
    q_t, rank_t = quality.transpose(1, 2, 0).copy(), rank.transpose(1, 2, 0).astype(np.int32)
    group = np.where(ignore, 1, G + 1).astype(np.int32).transpose(2, 0, 1)  # (G, P, A)
    real = ~crowd.T[:, :, None, None]  # (G, P, 1, 1): taken once only
    free = np.ones((G, P, A, thr.size), bool)
    n_det = np.asarray(n_det)
    for d in range(int(n_det.max(initial=0))):
        n = int(np.count_nonzero(n_det > d))  # the active problems are a prefix
        ok = free[:, :n] & (q_t[d, :, :n, None] >= thr)[:, :, None, :]
        key = (group[:, :n] + rank_t[d, :, :n, None])[..., None] * ok
        col = key.argmax(0)  # (n, A, T)
        hit = np.take_along_axis(key, col[None], 0)[0] > 0
        out[:n, d] = np.where(hit, col, -1)
        taken = (np.arange(G)[:, None, None, None] == col[None]) & hit[None] & real[:, :n]
        free[:, :n] &= ~taken
    return out


def _within(sizes: np.ndarray) -> np.ndarray:
    """Position of each element within its run, runs of ``sizes`` laid end to end.

    Example:
        >>> _within(np.array([2, 3])).tolist()
        [0, 1, 0, 1, 2]
    """
    sizes = np.asarray(sizes, np.int64)
    return np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)


def _blocks(dn: np.ndarray, gn: np.ndarray, width: int):
    """Problems (indices) grouped by instance count (power-of-two padding), most detections
    first, in blocks whose matcher arrays stay under :data:`WORK` elements."""
    pad = 1 << np.ceil(np.log2(np.maximum(gn, 1))).astype(np.int64)
    for g in np.unique(pad):
        idx = np.flatnonzero(pad == g)
        idx = idx[np.argsort(-dn[idx], kind="stable")]
        d = int(dn[idx[0]])
        step = max(1, WORK // max(d * int(g) + max(d, int(g)) * width, 1))
        for i in range(0, idx.size, step):
            yield idx[i : i + step]


def assign_pairs(
    d_problem: np.ndarray,
    g_problem: np.ndarray,
    g_ignore: np.ndarray,
    g_crowd: np.ndarray,
    pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
    thresholds,
) -> np.ndarray:
    """The greedy matching of every problem from its candidate pairs.

    Args:
        d_problem: ``(D,)`` problem of each detection, sorted; within a problem the
            detections are in visiting order (descending score).
        g_problem: ``(G,)`` problem of each instance, sorted (within a problem: column order).
        g_ignore: ``(G, A)`` instances ignored per area range (crowd ones included).
        g_crowd: ``(G,)`` crowd instances.
        pairs: ``(d, g, quality)``: the candidate pairs (same problem; the others never
            match), detection and instance indices into the arrays above.
        thresholds: ``(T,)`` minimum quality.

    Returns:
        int ``(D, A, T)``: the instance (an index into the instances) each detection took, -1
        none.

    Example:
        >>> d_problem, g_problem = np.array([0, 0, 1]), np.array([0, 1])
        >>> pairs = (np.array([0, 1, 2]), np.array([0, 0, 1]), np.array([0.7, 0.9, 0.2]))
        >>> assign_pairs(d_problem, g_problem, np.zeros((2, 1), bool), np.zeros(2, bool),
        ...              pairs, [0.5])[:, 0, 0].tolist()
        [0, -1, -1]
    """
    thr = np.asarray(thresholds, np.float64).reshape(-1)
    A = g_ignore.shape[1]
    out = np.full((d_problem.size, A, thr.size), -1, np.int64)
    pd_, pg, pq = (np.asarray(a) for a in pairs)
    if pd_.size == 0:
        return out
    n_prob = int(max(d_problem.max(initial=-1), g_problem.max(initial=-1))) + 1
    dn = np.bincount(d_problem, minlength=n_prob)
    gn = np.bincount(g_problem, minlength=n_prob)
    ds, gs = np.cumsum(dn) - dn, np.cumsum(gn) - gn  # first detection / instance of each
    active = np.flatnonzero((dn > 0) & (gn > 0))
    for blk in _blocks(dn[active], gn[active], A * thr.size):
        probs = active[blk]
        _solve(probs, dn, gn, ds, gs, d_problem, (pd_, pg, pq), g_ignore, g_crowd, thr, out)
    return out


def _solve(probs, dn, gn, ds, gs, d_problem, pairs, g_ignore, g_crowd, thr, out) -> None:
    """Pad one block of problems, match them and write each detection's instance."""
    P, D, G = probs.size, int(dn[probs].max()), int(gn[probs].max())
    slot = np.full(dn.size, -1)
    slot[probs] = np.arange(P)
    pd_, pg, pq = pairs
    sel = slot[d_problem[pd_]] >= 0
    p = slot[d_problem[pd_[sel]]]
    quality = np.full((P, D, G), -np.inf)
    quality[p, pd_[sel] - ds[probs][p], pg[sel] - gs[probs][p]] = pq[sel]
    ignore = np.ones((P, g_ignore.shape[1], G), bool)
    crowd = np.zeros((P, G), bool)
    gp = np.repeat(np.arange(P), gn[probs])
    gi = np.repeat(gs[probs], gn[probs]) + _within(gn[probs])
    ignore[gp, :, _within(gn[probs])] = g_ignore[gi]
    crowd[gp, _within(gn[probs])] = g_crowd[gi]
    col = greedy_assign(quality, ignore, crowd, dn[probs], thr)
    dp = np.repeat(np.arange(P), dn[probs])
    dr = _within(dn[probs])
    di = np.repeat(ds[probs], dn[probs]) + dr
    c = col[dp, dr]  # (n, A, T)
    out[di] = np.where(c >= 0, gs[probs][dp][:, None, None] + c, -1)
