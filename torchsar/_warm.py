"""Compile every numba kernel for the common input types ahead of use.

numba compiles a kernel the first time it is called with new argument types and keeps the
machine code in its on-disk cache (``__pycache__`` beside the sources). On a fresh install
that first call costs up to a minute for all kernels together; :func:`warm` (run by ``make
setup`` through ``scripts/warm_kernels.py``) pays it once, so the first evaluation, detector
call or test run does not. It runs every compiled path (the window CFARs, OS-CFAR, the speckle
filters, the region CFAR, object labelling and closing, the matching, the pixel ROC) on tiny
float32 and float64 batches (the window CFARs with and without a valid mask). Without numba (or with
``TORCHSAR_NUMBA=0``) it does nothing. :func:`warm_tables` computes the K and G0 CFARs'
default design tables into their on-disk cache.
"""

from __future__ import annotations

import time

import torch

from torchsar import _jit

__all__ = ["warm", "warm_tables"]


def _images(dtype: torch.dtype) -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    x = torch.empty(2, 1, 40, 40, dtype=torch.float64).exponential_(generator=g)
    x[..., 20, 20] = 80.0
    x[..., 10:13, 28:31] = 40.0
    return x.to(dtype)


def warm() -> float:
    """Call every compiled path once per common type; the seconds it took (0 when the
    kernels are off)."""
    if not _jit.enabled():
        return 0.0
    from torchsar import cfar, speckle
    from torchsar.metrics import Matching, RocAccumulator, ground_truth, match_batch
    from torchsar.objects import ObjectRules, discriminate
    from torchsar.region import region_cfar

    start = time.perf_counter()
    window = (
        *(cfar.ca, cfar.go, cfar.so, cfar.os, cfar.vi, cfar.ac, cfar.two_parameter),
        cfar.lognormal,  # the distribution CFARs' ring moments
    )
    for dtype in (torch.float32, torch.float64):
        x = _images(dtype)
        valid = torch.ones_like(x, dtype=torch.bool)
        valid[..., :4, :] = False
        for mask in (None, valid):
            for detector in window:
                detector(x, valid=mask)
        cfar.os_mask(x)  # the counting decision (float32)
        for name in ("lee", "enhanced_lee", "frost", "enhanced_frost", "gamma_map"):
            speckle.FILTERS[name](x, window=3)
        region_cfar(x)
        det = cfar.ca(x)  # detects the bright spots: objects to label and close
        for closing in (0, 2):
            obj = discriminate(det.statistic, det.threshold, rules=ObjectRules(closing=closing))
        ids = torch.zeros(x.shape[0], *x.shape[-2:], dtype=torch.int64)
        ids[:, 18:23, 18:23] = 1
        gt = ground_truth(ids.numpy())
        for kind in ("mask", "centroid"):  # the greedy assignment and the pixel joins
            match_batch(obj, gt, Matching(kind=kind))
        acc = RocAccumulator()
        target = torch.zeros_like(x, dtype=torch.bool)
        target[..., 18:23, 18:23] = True
        acc.update(det.statistic, target, detected=det.mask)
        with_inf = det.statistic.clone()
        with_inf[..., 0, 0] = -torch.inf  # the batch's finite range found by the kernel
        acc.update(with_inf, target, ~valid, detected=det.mask)
    return time.perf_counter() - start


def warm_tables() -> float:
    """Compute the K and G0 CFARs' log-t factors at their default design (``pfa = 1e-3``,
    one look, every ring size of the default window, borders included) into the on-disk
    cache (:func:`torchsar.cfar.log_t.log_t_exact`); the seconds it took. Kernels on or
    off, the first K or G0 detection then costs no calibration."""
    from torchsar import cfar

    start = time.perf_counter()
    x = _images(torch.float32)
    for detector in (cfar.k, cfar.g0):
        detector(x)
    return time.perf_counter() - start
