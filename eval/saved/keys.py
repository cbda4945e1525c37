"""Which dataset item a saved prediction refers to.

The one rule, for every format: a prediction names its image either by an **id** (COCO
results' ``image_id``, a points CSV's ``image_id`` column: an integer) or by a **name**
(COCO results' ``file_name``; a points CSV's ``image``, ``file_name`` or ``scene_id``
column: text). An id is the item's COCO id when the dataset has COCO ids (``coco:``
datasets); on a dataset without ids, integer ids are refused unless they are declared
1-based positions in dataset order (``positions``: ``ids="position"``, the ids
``torchsar-eval run --export-coco`` writes), since a file indexed another way would be
matched to the wrong images without a word. A name is matched to an item's name (as in
``per_image.csv``), else its file name, else its file name without extension, and never
taken for an id: a name ``"1"`` that no image has is an error, not the first image.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import PurePath

import numpy as np
from torch.utils.data import Dataset

from torchsar_eval.batches import as_dict
from torchsar_eval.errors import EvalError

__all__ = ["dataset_keys", "locate"]


def dataset_keys(dataset: Dataset) -> list[dict]:
    """Each item's ``name``, ``path`` and ``image_id`` where known, without reading the
    images when the dataset can say (``item_key``), else from each item's metadata."""
    key = getattr(dataset, "item_key", None)
    if key is not None:
        return [key(i) for i in range(len(dataset))]
    out = []
    for i in range(len(dataset)):
        meta = as_dict(dataset[i])["meta"]
        out.append({k: meta[k] for k in ("name", "path", "image_id") if meta.get(k) is not None})
    return out


def _unique_index(values: list[str | None]) -> dict[str, int]:
    """Value -> item for values held by exactly one item."""
    seen: dict[str, list[int]] = defaultdict(list)
    for i, v in enumerate(values):
        if v is not None:
            seen[v].append(i)
    return {v: items[0] for v, items in seen.items() if len(items) == 1}


def _by_name(keys: list[dict]) -> list[dict[str, int]]:
    names = [k.get("name") for k in keys]
    files = [PurePath(k.get("path") or k.get("name") or "").name or None for k in keys]
    stems = [PurePath(f).stem if f else None for f in files]
    return [
        _unique_index([str(n) if n is not None else None for n in names]),
        _unique_index(files),
        _unique_index(stems),
    ]


def locate(refs: np.ndarray, keys: list[dict], what: str, positions: bool = False) -> np.ndarray:
    """The item index of each reference (see the module docstring; ``positions``: integer
    ids are 1-based positions on a dataset without ids).

    Raises:
        EvalError: a reference no item has (naming the first and the count), or a name
            that several items share.
    """
    ids = [k.get("image_id") for k in keys]
    by_id = _unique_index(ids) if any(i is not None for i in ids) else None
    values = refs.tolist()
    if by_id is None and not positions and any(type(v) is not str for v in values):
        raise EvalError(
            f"{what}: the predictions name images by integer id, but the dataset "
            "has no image ids: give each prediction its image's file_name (COCO) "
            "or name (CSV), or declare the ids 1-based positions in dataset order "
            "with ids='position' (--param NAME.ids=position)"
        )
    memo: dict[object, int] = dict.fromkeys(values, -1)
    tables = _by_name(keys) if any(type(ref) is str for ref in memo) else []  # names: by need
    for ref in memo:
        memo[ref] = _find(ref, by_id, tables, len(keys))
    out = np.array([memo[ref] for ref in values], dtype=np.int64).reshape(len(values))
    missing = [ref for ref, i in memo.items() if i < 0]
    if missing:
        hint = (
            " (it is given as a name; an integer id goes in the image_id field or column)"
            if isinstance(missing[0], str) and missing[0].isdigit()
            else ""
        )
        raise EvalError(
            f"{what}: {len(missing)} image(s) not in the dataset, e.g. "
            f"{missing[0]!r}{hint} (images are matched by COCO id, or by name, "
            "file name or file stem; ids of other datasets count from 1 in "
            "dataset order)"
        )
    return out


def _find(ref: object, by_id: dict | None, tables: list[dict[str, int]], n: int) -> int:
    if isinstance(ref, str):  # a name: never an id
        for table in tables:
            if ref in table:
                return table[ref]
        return -1
    if by_id is not None:
        return by_id.get(ref, -1)
    return ref - 1 if isinstance(ref, int) and 1 <= ref <= n else -1
