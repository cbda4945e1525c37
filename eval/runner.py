"""The dataset-scale runner: one pass per detector over batches, states merged by addition.

Each batch is loaded once (and moved to the run's device once) and given to every
detector; each output is added to its detector's :class:`~torchsar_eval.result.DetectorResult`
(pixel counts and ROC, the objects matched to the ground truth, the object state). Images of
different sizes (folder datasets) are grouped into same-size sub-batches
(:func:`~torchsar_eval.batches.batches`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

import torch
from torch import Tensor
from torch.utils.data import Dataset
from tqdm.auto import tqdm

from torchsar.detection import Detection
from torchsar.objects import Objects
from torchsar_eval.batches import batches
from torchsar_eval.detector import Detector
from torchsar_eval.result import DetectorResult, Scoring
from torchsar_eval.scoring import batch_truth

__all__ = ["run_detectors", "to_cpu"]


def to_cpu(out: Detection | Objects) -> Detection | Objects:
    """A detector's output with its tensors on the CPU (objects already are)."""
    if isinstance(out, Detection) and out.statistic.device.type != "cpu":
        labels = None if out.labels is None else out.labels.cpu()
        return Detection(out.mask.cpu(), out.statistic.cpu(), out.threshold.cpu(), labels)
    return out


def run_detectors(
    dataset: Dataset,
    detectors: list[Detector],
    *,
    batch_size: int = 16,
    preprocess: Callable[[Tensor], Tensor] | None = None,
    scoring: Scoring | None = None,
    name: str = "",
    progress: bool = True,
    desc: str = "",
    on_batch: Callable[[dict, dict], None] | None = None,
    device: torch.device | str | None = None,
    default_class: str = "target",
    skip_bad: bool = False,
    overlap: bool = True,
) -> list[DetectorResult]:
    """Run every detector over the dataset and accumulate its pixel and object states.

    Args:
        dataset: yields dicts with ``image``, ``mask``, ``instances``, ``ignore``, ``meta``.
        detectors: the detectors to run (with resolved options).
        batch_size: images per batch.
        preprocess: optional image stage applied once per batch before every detector (e.g. a
            speckle filter); its time is charged to every detector's ``ms_per_image``.
        scoring: discrimination, matching and bootstrap settings (default :class:`Scoring`).
        name: dataset name (part of each image's bootstrap key).
        progress: show a progress bar.
        desc: progress-bar label.
        on_batch: called as ``on_batch(batch, {detector: Objects})`` after each batch (e.g.
            a COCO exporter).
        device: where the detectors run: each batch (and each ``torch.nn.Module``
            detector) is moved there, outputs come back to the CPU for scoring.
        default_class: the class of objects without one (COCO-compatible scoring).
        skip_bad: when a batch fails (an image smaller than a detector's window, say),
            score its images one by one and skip, naming them, those that fail alone;
            by default the error stops the run.
        overlap: run the detectors on the next batch (on a second thread) while this one is
            scored, so that neither a GPU nor the CPU waits for the other (on two cores, 1.4
            to 1.6x the images per second of one worker). Scoring stays in batch order on
            this thread, so every number is the same either way; a batch's error still
            surfaces after the batches before it are scored. The price is one more batch in
            memory; ``False`` runs detection and scoring one after the other.
    """
    scoring = Scoring() if scoring is None else scoring
    device = None if device is None else torch.device(device)
    for det in detectors:
        if isinstance(det.fn, torch.nn.Module):
            det.fn.eval()
            if device is not None:
                det.fn.to(device)
    results = [DetectorResult(det, scoring, default_class=default_class) for det in detectors]
    n_batches = -(-len(dataset) // batch_size) if len(dataset) else 0
    skipped: list = []

    def detect(batch: dict) -> tuple:
        return _outputs(results, batch, preprocess, device)

    def score(ahead, batch: dict, detected: Future, unread_before: list) -> None:
        skipped.extend(unread_before)  # those skipped while this batch was gathered
        try:
            parts = [(batch, detected.result())]
        except Exception:
            if not skip_bad or len(batch["meta"]) == 0:
                raise

            def alone(one: dict) -> tuple:  # on the detectors' thread: never two at once
                return ahead.submit(detect, one).result()

            parts = list(_one_by_one(batch, alone, skipped))
        for part, (outs, seconds) in parts:
            _add(results, part, outs, seconds, name or desc, scoring, on_batch)

    # the next batch's detectors run while this one is scored (in order, on this thread)
    with ThreadPoolExecutor(1, thread_name_prefix="torchsar-detect") as ahead:
        if not overlap:
            ahead = _Inline()
        unread: list = []  # images that could not be read, named in the order scored
        pending, seen = None, 0
        for batch in tqdm(
            batches(dataset, batch_size, unread),
            total=n_batches,
            desc=desc,
            disable=not progress,
            leave=False,
        ):
            detected = ahead.submit(detect, batch)
            if pending is not None:
                score(ahead, *pending)
            pending, seen = (batch, detected, unread[seen:]), len(unread)
        if pending is not None:
            score(ahead, *pending)
        skipped.extend(unread[seen:])
    for res in results:
        res.skipped = list(skipped)
        if res.gallery is not None:
            t0 = time.perf_counter()
            res.gallery.settle()  # the cases still among the best: built now
            res.object_seconds += time.perf_counter() - t0
    return results


class _Inline:
    """An executor that runs each call at once, on this thread (``overlap=False``)."""

    def submit(self, fn: Callable, *args) -> Future:
        done: Future = Future()
        try:
            done.set_result(fn(*args))
        except Exception as exc:
            done.set_exception(exc)
        return done


def _add(results, part: dict, outs, seconds, name: str, scoring: Scoring, on_batch) -> None:
    """Score one batch's outputs into every detector's state (the ground truth built once)."""
    t0 = time.perf_counter()
    truth = batch_truth(part, name, scoring.bootstrap_unit)
    t_truth = (time.perf_counter() - t0) / max(len(results), 1)  # shared
    found = {}
    for res, out, sec in zip(results, outs, seconds, strict=True):
        res.seconds += sec
        res.images += part["image"].shape[0]
        res.object_seconds += t_truth
        found[res.detector.name] = res.add(out, part, truth)
    if on_batch is not None:
        on_batch(part, found)


def _outputs(results: list[DetectorResult], batch: dict, preprocess, device) -> tuple:
    """Every detector's output on one batch (on the CPU) and its seconds (the shared
    preprocessing charged to each); all or nothing, so a failure adds nothing."""
    x = batch["image"] if device is None else batch["image"].to(device)
    t0 = time.perf_counter()
    if preprocess is not None:
        x = preprocess(x)
    t_pre = time.perf_counter() - t0
    outs, seconds = [], []
    for res in results:
        t0 = time.perf_counter()
        outs.append(to_cpu(res.detector(x, batch["meta"])))
        seconds.append(time.perf_counter() - t0 + t_pre)
    return outs, seconds


def _one_by_one(batch: dict, detect: Callable[[dict], tuple], skipped: list):
    """A failed batch image by image (``detect``: one image's outputs and seconds): the
    images that fail alone are skipped (named in ``skipped`` with the error), the others
    scored as in any batch."""
    for i, meta in enumerate(batch["meta"]):
        one = {k: v[i : i + 1] for k, v in batch.items() if k not in ("meta", "truth_only")}
        one["meta"] = [meta]
        if batch.get("truth_only"):
            one["truth_only"] = True
        try:
            yield one, detect(one)
        except Exception as exc:
            where = meta.get("path") or meta.get("name") or f"item {meta.get('index')}"
            message = " ".join(f"{type(exc).__name__}: {exc}".split())
            skipped.append((str(where), message))
