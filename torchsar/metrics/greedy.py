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
arrays (detections and instances numbered by problem) and returns, per detection, area
range and threshold, the instance it took; it visits only the candidate pairs (no padded
problem arrays). :func:`greedy_assign` is the same matching on padded dense arrays (one
problem of a few detections, or a reference). With the compiled kernels
(:mod:`torchsar._jit`) :func:`assign_pairs` makes the same choices in one compiled loop
over the pairs (:func:`torchsar.metrics._match_kernels.greedy_pairs`).
"""

from __future__ import annotations

import numpy as np

from torchsar import _jit

__all__ = ["assign_pairs", "greedy_assign"]


def _row_ranks(q: np.ndarray) -> np.ndarray:
    """Rank of each entry within its last-axis row, ascending by value then by position.

    Examples:
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

    Examples:
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


def assign_pairs(
    d_problem: np.ndarray,
    g_problem: np.ndarray,
    g_ignore: np.ndarray,
    g_crowd: np.ndarray,
    pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
    thresholds,
) -> np.ndarray:
    """The greedy matching of every problem from its candidate pairs, without padding: one
    step per detection rank (the rank-``k`` detections of all problems at once), each
    visiting only the candidate pairs of those detections.

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

    Examples:
        >>> d_problem, g_problem = np.array([0, 0, 1]), np.array([0, 1])
        >>> pairs = (np.array([0, 1, 2]), np.array([0, 0, 1]), np.array([0.7, 0.9, 0.2]))
        >>> assign_pairs(d_problem, g_problem, np.zeros((2, 1), bool), np.zeros(2, bool),
        ...              pairs, [0.5])[:, 0, 0].tolist()
        [0, -1, -1]
    """
    thr = np.minimum(np.asarray(thresholds, np.float64).reshape(-1), 1 - 1e-10)
    d_problem = np.asarray(d_problem, np.int64)
    A, D = g_ignore.shape[1], d_problem.size
    out = np.full((D, A, thr.size), -1, np.int64)
    pd_, pg, pq = (np.asarray(a) for a in pairs)
    if pd_.size == 0:
        return out
    # pairs by detection, then quality, then instance: a pair's rank among its detection's
    # pairs orders pycocotools' choice (highest quality; ties: the later instance)
    order = np.lexsort((pg, pq, pd_))
    pd_, pg, pq = pd_[order].astype(np.int64), pg[order].astype(np.int64), pq[order]
    if _jit.enabled():  # one compiled call (the same choices)
        from torchsar.metrics import _match_kernels

        ignore, crowd = np.ascontiguousarray(g_ignore, bool), np.asarray(g_crowd, bool)
        _match_kernels.greedy_pairs(pd_, pg, pq.astype(np.float64), ignore, crowd, thr, out)
        return out
    per_det = np.bincount(pd_, minlength=D)
    rank = np.arange(pd_.size) - (np.cumsum(per_det) - per_det)[pd_]
    # the key (0: not a candidate) is largest for the choice: counted instances first
    top = int(per_det.max()) + 1
    key = np.where(g_ignore[pg], 1, top + 1) + rank[:, None]  # (pairs, A), unique per det
    reach = pq[:, None] >= thr  # (pairs, T)
    dn = np.bincount(d_problem)
    step = (np.arange(D) - (np.cumsum(dn) - dn)[d_problem])[pd_]  # the detection's rank
    by_step = np.argsort(step, kind="stable")  # (detections stay in order within a step)
    bounds = np.searchsorted(step[by_step], np.arange(int(step.max()) + 2))
    free = np.ones((g_ignore.shape[0], A, thr.size), bool)
    real = ~np.asarray(g_crowd, bool)  # a crowd instance may be taken again and again
    for k in range(bounds.size - 1):
        idx = by_step[bounds[k] : bounds[k + 1]]
        if idx.size == 0:
            continue
        g, det = pg[idx], pd_[idx]
        kk = key[idx][:, :, None] * (free[g] & reach[idx][:, None, :])  # (pairs, A, T)
        starts = np.flatnonzero(np.append(True, det[1:] != det[:-1]))
        best = np.maximum.reduceat(kk, starts, axis=0)
        seg = np.repeat(np.arange(starts.size), np.diff(np.append(starts, idx.size)))
        p, a, t = np.nonzero((kk == best[seg]) & (kk > 0))
        out[det[p], a, t] = g[p]
        taken = real[g[p]]
        free[g[p][taken], a[taken], t[taken]] = False
    return out
