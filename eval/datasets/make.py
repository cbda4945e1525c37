"""``make_dataset``: a dataset from its name (scheme, path and options)."""

from __future__ import annotations

import numbers
from collections.abc import Callable

from torch.utils.data import Dataset

from torchsar.io import FileFormatError
from torchsar_eval.datasets.annotated import coco_from_spec, voc_from_spec
from torchsar_eval.datasets.base import BadItemError
from torchsar_eval.datasets.folder import folder_from_spec
from torchsar_eval.datasets.hrsid import hrsid_from_spec
from torchsar_eval.datasets.phoenix import phoenix_from_spec
from torchsar_eval.datasets.scene import scene_from_spec
from torchsar_eval.datasets.sicd import sicd_from_spec
from torchsar_eval.datasets.sim import DEFAULT_N, SimDataset
from torchsar_eval.datasets.spec import DatasetSpec, parse_spec
from torchsar_eval.errors import EvalError

__all__ = ["DATASETS", "MAX_N", "make_dataset", "own_count"]

MAX_N = 10_000_000
"""Most images per named dataset in one run (larger datasets: split them into runs)."""

DATASETS = (
    "sim-chips",
    "sim-scenes",
    "folder:PATH",
    "coco:FILE.json",
    "voc:DIR",
    "hrsid:DIR",
    "phoenix:DIR",
    "sicd:FILE",
    "scene:FILE",
    "store:DIR",
)


def store_from_spec(spec: DatasetSpec, limit: int | None) -> Dataset:
    """``store:DIR``: a store written by ``torchsar-eval make-dataset`` (no options)."""
    from torchsar_eval.store import StoreDataset  # the store writer builds on make_dataset

    spec.check_keys(())
    return StoreDataset(spec.path, limit=limit)


_SCHEMES: dict[str, Callable[[DatasetSpec, int | None], Dataset]] = {
    "folder": folder_from_spec,
    "coco": coco_from_spec,
    "voc": voc_from_spec,
    "hrsid": hrsid_from_spec,
    "phoenix": phoenix_from_spec,
    "sicd": sicd_from_spec,
    "scene": scene_from_spec,
    "store": store_from_spec,
}


def own_count(spec: str) -> tuple[str, int | None]:
    """Split a dataset's own ``n=N`` option off its name: ``"sim-scenes?n=4"`` -> ``("sim-scenes",
    4)``; the other options stay in place.

    Examples:
        >>> own_count("folder:imgs?n=10&type=display")
        ('folder:imgs?type=display', 10)
        >>> own_count("sim-chips")
        ('sim-chips', None)
    """
    head, _, query = spec.partition("?")
    kept, own = [], None
    for kv in filter(None, query.split("&")):
        key, _, value = kv.partition("=")
        if key != "n":
            kept.append(kv)
            continue
        if not (value.isascii() and value.isdigit()) or int(value) > MAX_N:
            raise EvalError(
                f"dataset option n={value[:20]!r} in {spec[:80]!r} must be a whole "
                f"number from 0 to {MAX_N:,}"
            )
        own = int(value)
    return head + ("?" + "&".join(kept) if kept else ""), own


def make_dataset(spec: str, *, n: int | None = None, seed: int = 0) -> Dataset:
    """Build a dataset from its name (see :mod:`torchsar_eval.datasets`); ``n`` limits its size.

    A dataset's own ``n=N`` option (``"sim-scenes?n=16"``, ``"folder:imgs?n=100"``) takes
    precedence over ``n``, so one run can take 1,000 chips and 4 scenes.

    Raises:
        EvalError: unknown scheme or option, missing folder, unpairable files; a file that
            cannot be read while building raises :class:`BadItemError` naming it.
    """
    if n is not None and (isinstance(n, bool) or not isinstance(n, numbers.Integral)):
        raise EvalError(f"{{opt:n}}{n!r}: must be a whole number")
    if n is not None and n < 0:
        raise EvalError(f"{{opt:n}}{n}: must be >= 0")
    spec, own = own_count(spec)
    n = n if own is None else own
    if spec in DEFAULT_N:
        return SimDataset(spec, DEFAULT_N[spec] if n is None else n, seed)
    build = _SCHEMES.get(spec.partition(":")[0]) if ":" in spec else None
    if build is None:
        raise EvalError(f"unknown dataset {spec!r}; valid: {', '.join(DATASETS)}")
    try:
        return build(parse_spec(spec), n)
    except FileFormatError as exc:
        raise BadItemError(exc.path, str(exc)) from exc
