"""Items to batches: the dataset wrappers of a run (its positions in the dataset, ground
truth only, unreadable items skipped) and same-size batches of them."""

from __future__ import annotations

from collections.abc import Iterator

import torch
from torch.utils.data import DataLoader, Dataset

from torchsar_eval.datasets.base import BadItemError
from torchsar_eval.items import Item

__all__ = ["Indexed", "SkipBad", "TruthOnly", "as_dict", "batches"]


def as_dict(item):
    """A dataset item as the harness's dict (a typed :class:`~torchsar_eval.items.Item` is
    converted; a dict is itself)."""

    return item.as_dict() if isinstance(item, Item) else item


def _stack(items: list[dict]) -> dict:
    out = {
        k: torch.stack([it[k] for it in items]) for k in ("image", "mask", "instances", "ignore")
    }
    out["meta"] = [it["meta"] for it in items]
    if all("targets" in it for it in items):  # ground truth as given (annotation files)
        out["targets"] = [it["targets"] for it in items]
    if all(it.get("truth_only") for it in items):  # images not read: nothing to measure on
        out["truth_only"] = True
    return out


class TruthOnly(Dataset):
    """A dataset read for its ground truth only (``dataset.truth(i)`` where it has one):
    what scoring saved predictions needs, without decoding images."""

    def __init__(self, dataset: Dataset) -> None:
        self.dataset = dataset
        self._get = getattr(dataset, "truth", dataset.__getitem__)

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, i: int) -> dict:
        item = as_dict(self._get(i))
        if isinstance(item, dict) and "bad" not in item:
            item["truth_only"] = True
        return item


class SkipBad(Dataset):
    """A dataset whose unreadable items (:class:`~torchsar_eval.datasets.BadItemError`) are returned
    as ``{"bad": path, "error": message}`` markers instead of stopping the run."""

    def __init__(self, dataset: Dataset) -> None:
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, i: int) -> dict:
        try:
            return as_dict(self.dataset[i])
        except BadItemError as exc:
            return {"bad": str(exc.path), "error": str(exc)}


class Indexed(Dataset):
    """Items ``indices`` of a dataset, each with its index in the dataset as
    ``meta["index"]`` (the order key of exact AP and of exported image ids)."""

    def __init__(self, dataset: Dataset, indices) -> None:
        self.dataset, self.indices = dataset, list(indices)

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, i: int) -> dict:
        item = as_dict(self.dataset[self.indices[i]])
        if "meta" in item:
            item["meta"] = {**item["meta"], "index": self.indices[i]}
        return item


def batches(dataset: Dataset, batch_size: int, skipped: list | None = None) -> Iterator[dict]:
    """Yield stacked batches; consecutive images of different sizes split a batch; items
    marked bad by :class:`SkipBad` are left out and listed in ``skipped``. Each image's
    ``meta["index"]`` is its position in ``dataset`` unless it has one (see
    :class:`Indexed`)."""
    loader = DataLoader(dataset, batch_size=batch_size, shuffle=False, collate_fn=list)
    position = 0
    for items in loader:
        group: list[dict] = []
        for it in map(as_dict, items):
            position += 1
            if "bad" in it:
                if skipped is not None:
                    skipped.append((it["bad"], it["error"]))
                continue
            it["meta"] = {"index": position - 1, **it["meta"]}
            if group and it["image"].shape != group[0]["image"].shape:
                yield _stack(group)
                group = []
            group.append(it)
        if group:
            yield _stack(group)
