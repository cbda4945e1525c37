from __future__ import annotations

import pandas as pd
import pytest
import torch

from torchsar.errors import InputValueError
from torchsar_eval.registry import BUILTIN
from torchsar_eval.runner import run_detectors


class ListDataset(torch.utils.data.Dataset):
    def __init__(self, images):
        self.images = images

    def __len__(self):
        return len(self.images)

    def __getitem__(self, i):
        img = self.images[i]
        return {
            "image": img,
            "mask": torch.zeros_like(img, dtype=torch.bool),
            "instances": torch.zeros_like(img, dtype=torch.int32),
            "ignore": torch.zeros_like(img, dtype=torch.bool),
            "meta": {"name": str(i)},
        }


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -1.0])
def test_bad_pixels_raise_typed_error(bad):
    img = torch.ones(1, 32, 32)
    img[0, 3, 3] = bad
    with pytest.raises(InputValueError):
        run_detectors(ListDataset([img]), [BUILTIN["ca"]], progress=False)


def test_results_do_not_depend_on_batch_size():
    g = torch.Generator().manual_seed(0)
    imgs = [torch.empty(1, 40, 40).exponential_(generator=g) for _ in range(5)]
    imgs.insert(2, torch.empty(1, 30, 30).exponential_(generator=g))  # a size change mid-batch
    runs = [
        run_detectors(ListDataset(imgs), [BUILTIN["ca"]], batch_size=b, progress=False)[0]
        for b in (1, 4, 16)
    ]
    for r in runs[1:]:
        assert r.pixels == runs[0].pixels
        assert r.objects == runs[0].objects
        assert torch.equal(r.roc.clutter_hits, runs[0].roc.clutter_hits)


def test_empty_dataset():
    (res,) = run_detectors(ListDataset([]), [BUILTIN["ca"]], progress=False)
    assert res.images == 0 and res.roc.targets == 0 and res.objects.images == 0
    assert res.objects.metrics()["tp"] == 0


def test_preprocess_runs_before_detectors():
    seen = []

    def stage(x):
        seen.append(x.shape)
        return x * 0 + 1.0  # flat image: CA detects nothing

    img = torch.ones(1, 32, 32)
    img[0, 16, 16] = 100.0
    (res,) = run_detectors(ListDataset([img]), [BUILTIN["ca"]], preprocess=stage, progress=False)
    assert seen == [(1, 1, 32, 32)]
    assert res.pixels.fp == 0


def test_a_detector_that_writes_into_its_input_corrupts_nothing_after_it():
    """A detector zeroing its images (and emptying the metadata) in place: ``ca`` after it,
    and the scoring, see the batch as it was (on the code before, ``ca`` lost every
    detection)."""
    import torchsar_eval as te
    from torchsar.cfar import ca

    def vandal(images, meta):
        images.mul_(0)
        for m in meta:
            m.clear()
        return ca(images + 1.0)

    alone = te.evaluate("sim-chips", ["ca"], n=6, progress=False).summary
    both = te.evaluate(
        "sim-chips", [te.Detector("vandal", vandal), "ca"], n=6, progress=False
    ).summary
    rows = both[both.detector == "ca"].drop(columns=["detector"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(rows, alone.drop(columns=["detector"]).reset_index(drop=True))
    assert int(alone.tp.iloc[0]) > 0


class _Mixed(ListDataset):
    """Images of two sizes, one that cannot be read (index 3)."""

    def __getitem__(self, i):
        if i == 3:
            return {"bad": "item 3", "error": "OSError: unreadable"}
        item = super().__getitem__(i)
        item["mask"][0, 11:14, 11:14] = True  # the planted target (see _mixed_images)
        item["instances"][0, 11:14, 11:14] = 1
        return item


def _picky(images, meta):
    """CA, but failing on any batch holding the image named "5"."""
    from torchsar.cfar import ca

    if any(m["name"] == "5" for m in meta):
        raise ValueError("image 5 is not for me")
    return ca(images)


def _mixed_images() -> list[torch.Tensor]:
    g = torch.Generator().manual_seed(3)
    sizes = [40, 40, 30, 40, 40, 40, 30, 30, 40]
    imgs = [torch.empty(1, s, s).exponential_(generator=g) for s in sizes]
    for img in imgs:
        img[0, 11:14, 11:14] = 80.0  # a target for the object stage
    return imgs


def _run(overlap: bool, detectors, order: list | None = None, **kw):
    def record(part, found):
        order.append(([m["name"] for m in part["meta"]], sorted(found)))

    return run_detectors(
        _Mixed(_mixed_images()),
        detectors,
        batch_size=2,
        progress=False,
        overlap=overlap,
        on_batch=None if order is None else record,
        **kw,
    )


def test_overlapping_detection_with_scoring_changes_nothing():
    """Detection one batch ahead on a second thread: the same states, the same skipped
    images in the same order, the same batches given to ``on_batch`` in the same order (a
    failing batch scored image by image, an unreadable image, size changes)."""
    import torchsar_eval as te

    dets = [BUILTIN["ca"], te.Detector("picky", _picky), BUILTIN["os"]]
    orders: dict[bool, list] = {True: [], False: []}
    runs = {ov: _run(ov, dets, orders[ov], skip_bad=True) for ov in (True, False)}
    assert orders[True] == orders[False] and len(orders[True]) > 4
    for a, b in zip(runs[True], runs[False], strict=True):
        assert a.pixels == b.pixels and a.objects == b.objects and a.images == b.images
        assert torch.equal(a.roc.clutter_hits, b.roc.clutter_hits)
        assert a.objects.metrics() == pytest.approx(b.objects.metrics(), nan_ok=True)
        assert a.skipped == b.skipped
    assert [name for name, _ in runs[True][0].skipped] == ["item 3", "5"]
    assert runs[True][0].objects.metrics()["tp"] > 0


def test_a_failing_batch_stops_the_run_after_the_batches_before_it_are_scored():
    import torchsar_eval as te

    for ov in (True, False):
        order: list = []
        with pytest.raises(ValueError, match="image 5"):
            _run(ov, [te.Detector("picky", _picky)], order)
        assert [names for names, _ in order] == [["0", "1"], ["2"]]


def test_the_detectors_run_on_a_second_thread_only_when_overlapping():
    import threading

    import torchsar_eval as te

    threads: dict[bool, set] = {True: set(), False: set()}
    for ov in (True, False):

        def where(images, ov=ov):
            from torchsar.cfar import ca

            threads[ov].add(threading.current_thread().name)
            return ca(images)

        _run(ov, [te.Detector("where", where)])
    assert all(t.startswith("torchsar-detect") for t in threads[True])
    assert threads[False] == {threading.current_thread().name}


def test_a_detector_is_never_called_twice_at_once():
    """With overlap, a batch that fails is rerun image by image on the detectors' thread,
    queued behind the next batch: a detector never runs on two threads at once."""
    import threading
    import time

    import torchsar_eval as te

    lock, active, most = threading.Lock(), [0], [0]

    def exclusive(images, meta):
        with lock:
            active[0] += 1
            most[0] = max(most[0], active[0])
        time.sleep(0.01)  # long enough for a second caller to overlap, were there one
        try:
            return _picky(images, meta)
        finally:
            with lock:
                active[0] -= 1

    (res,) = _run(True, [te.Detector("exclusive", exclusive)], skip_bad=True)
    assert most[0] == 1
    assert [name for name, _ in res.skipped] == ["item 3", "5"]
