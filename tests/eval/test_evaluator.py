"""The incremental evaluator: ``update`` / ``compute`` over batches in any order and any
split (merged with ``+``) equal :func:`torchsar_eval.evaluate` on the whole, table for table;
a ``state_dict`` round trip changes nothing and holds data only; it runs inside a plain
PyTorch validation loop; typed items are a dataset ``evaluate`` scores."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from torch.utils.data import DataLoader, Dataset

import torchsar_eval as te
from torchsar.objects import Objects
from torchsar_eval.items import ImageMeta, Item, Targets

SIZE = 40
TABLES = ("summary", "froc", "pr", "breakdown", "per_image", "errors", "scr", "coco")


class Ships(Dataset):
    """Seeded typed items: bright rectangles (two classes, some overlapping) on clutter."""

    def __init__(self, n: int, seed: int = 0) -> None:
        self.n, self.seed = n, seed

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> Item:
        rng = np.random.default_rng([self.seed, i])
        image = rng.exponential(1.0, (SIZE, SIZE)).astype(np.float32)
        boxes, classes = [], []
        for _ in range(int(rng.integers(0, 4))):
            h, w = rng.integers(3, 9, 2)
            r, c = rng.integers(0, SIZE - 9, 2)
            image[r : r + h, c : c + w] += float(rng.uniform(3, 20))
            boxes.append([r, c, r + h, c + w])
            classes.append("ship" if h * w > 30 else "boat")
        targets = Targets.build(np.array(boxes, float).reshape(-1, 4), classes=classes)
        return Item(torch.from_numpy(image)[None], targets, ImageMeta(f"img{i}", index=i))


def detect(images: torch.Tensor) -> list[dict]:
    """A toy detector: the boxes of the connected bright regions, scored by their peak and
    labelled by their size (per image, torchvision style)."""
    from scipy import ndimage

    out = []
    for x in images[:, 0].numpy():
        lab, _ = ndimage.label(x > 2.5)
        boxes, scores, labels = [], [], []
        for k, sl in enumerate(ndimage.find_objects(lab), start=1):
            r, c = sl
            boxes.append([c.start, r.start, c.stop, r.stop])
            scores.append(float(x[lab == k].max()))
            labels.append(1 if (r.stop - r.start) * (c.stop - c.start) > 30 else 2)
        out.append(
            {
                "boxes": torch.tensor(boxes, dtype=torch.float64).reshape(-1, 4),
                "scores": torch.tensor(scores, dtype=torch.float64),
                "labels": torch.tensor(labels, dtype=torch.int64),
            }
        )
    return out


NAMES = {1: "ship", 2: "boat"}


def as_objects(images: torch.Tensor) -> Objects:
    """The same detector as the harness calls it (a batch -> one Objects)."""
    preds = detect(images)
    return Objects.from_boxes(
        [p["boxes"].numpy() for p in preds],
        [p["scores"].numpy() for p in preds],
        shape=(SIZE, SIZE),
        box_format="xyxy",
        planes=len(preds),
        classes=[NAMES[int(v)] for p in preds for v in p["labels"]],
    )


SCORING = te.Scoring(matching=te.Matching(kind="box"), replicates=30, coco_compatible=True)


def _loop(ds, order, cut: int | None = None) -> te.Evaluator:
    """Batches of 3 in ``order``; with ``cut``, two evaluators (images before and after it
    in that order) merged."""
    parts = [order] if cut is None else [order[:cut], order[cut:]]
    evs = []
    for part in parts:
        ev = te.Evaluator("toy", SCORING)
        for k in range(0, len(part), 3):
            items = [ds[int(i)] for i in part[k : k + 3]]
            images = torch.stack([it.image for it in items])
            ev.update(detect(images), items, images=images, categories=NAMES)
        evs.append(ev)
    return evs[0] if len(evs) == 1 else evs[1] + evs[0]


@pytest.fixture(scope="module")
def whole():
    ds = Ships(13)
    return te.evaluate({"dataset": ds}, {"toy": as_objects}, scoring=SCORING, progress=False)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 1000), cut=st.one_of(st.none(), st.integers(1, 12)))
def test_batches_in_any_order_and_split_equal_evaluate(whole, seed, cut):
    ds = Ships(13)
    order = np.random.default_rng(seed).permutation(13)
    got = _loop(ds, order, cut).compute("dataset")
    for name in TABLES:
        pd.testing.assert_frame_equal(getattr(got, name), getattr(whole, name), obj=name)


def test_state_dict_round_trip_is_data_only(whole):
    ds = Ships(13)
    ev = _loop(ds, np.arange(13))
    state = ev.state_dict()
    json.dumps(state["tree"])  # plain values only
    assert all(isinstance(a, np.ndarray) and not a.dtype.hasobject for a in state["arrays"])
    again = te.Evaluator("toy", SCORING)
    again.load_state_dict(state)
    for name in TABLES:
        pd.testing.assert_frame_equal(
            getattr(again.compute("dataset"), name), getattr(whole, name), obj=name
        )
    with pytest.raises(te.EvalError, match="state_dict"):
        again.load_state_dict({"format": "other"})


def test_in_a_plain_pytorch_validation_loop(whole):
    """A torch module, a DataLoader and torch.no_grad(), as a training script has them."""

    class Toy(torch.nn.Module):
        def forward(self, x: torch.Tensor) -> list[dict]:
            return detect(x)

    model = Toy().eval()
    loader = DataLoader(Ships(13), batch_size=4, collate_fn=list)
    ev = te.Evaluator("toy", SCORING)
    with torch.no_grad():
        for items in loader:
            images = torch.stack([it.image for it in items])
            ev.update(model(images), items, images=images, categories=NAMES)
    res = ev.compute("dataset")
    pd.testing.assert_frame_equal(res.summary, whole.summary)
    assert res.row("dataset", "toy").classes == "per-class"


def test_bad_updates_are_clear_errors():
    ev = te.Evaluator("toy")
    with pytest.raises(te.EvalError, match="2 predictions for 1 targets"):
        ev.update([{"boxes": [], "scores": []}] * 2, [{"boxes": []}])
    with pytest.raises(te.EvalError, match="target 0 boxes must be finite"):
        ev.update([{"boxes": [], "scores": []}], [{"boxes": [[0.0, 0, np.nan, 1]]}])
    with pytest.raises(te.EvalError, match="label 3 is not one of the categories"):
        ev.update(
            [{"boxes": [[0, 0, 2, 2]], "scores": [1.0], "labels": [3]}],
            [{"boxes": [[0, 0, 2, 2]], "labels": [1]}],
            categories=NAMES,
        )
    ev.update([], [])  # an empty batch is valid
    assert ev.compute().summary.images.tolist() == [0]
