"""Benchmark cases: cost of the object stage in the default run.

``ours`` is the default ``torchsar-eval run`` scoring of every registered detector
(detector, pixel counts, pixel ROC, then ground truth, discrimination, matching and the
object state with its bootstrap); ``reference`` is the same pass without the object stage.
The ratio ``reference / ours`` is the run's time without the object stage over the time with
it: >= 0.83 means the object stage adds at most 20 %.
Run: ``python scripts/benchmark.py --topic objects --repeat 1``.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

import torchsar as ts
from torchsar.metrics import RocAccumulator, pixel_counts
from torchsar_eval.commands.run import DEFAULT_MATCH, DEFAULT_RULES
from torchsar_eval.registry import BUILTIN
from torchsar_eval.result import Scoring
from torchsar_eval.runner import run_detectors


def _dataset(kind: str, n: int) -> list[dict]:
    b = (ts.simulate.chips if kind == "chips" else ts.simulate.scenes)(n, seed=0)
    return [{**b[i], "meta": {"name": str(i), **b[i]["meta"]}} for i in range(n)]


def _pixels_only(items: list[dict], batch: int) -> None:
    """The run without the object stage: every detector, pixel counts and pixel ROC."""
    for k in range(0, len(items), batch):
        part = items[k : k + batch]
        x = torch.stack([it["image"] for it in part])
        mask = torch.stack([it["mask"] for it in part])
        ignore = torch.stack([it["ignore"] for it in part])
        for spec in BUILTIN.values():
            det = spec(x)
            pixel_counts(det.mask, mask, ignore=ignore)
            RocAccumulator().update(det.statistic, mask, ignore)


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    scoring = Scoring(DEFAULT_RULES, DEFAULT_MATCH)
    out = []
    for kind, n in (("chips", 64), ("scenes", 4)):
        items = _dataset(kind, n)
        out.append(
            (
                f"default run, sim-{kind} x{n}, all detectors: without / with object stage",
                lambda items=items: run_detectors(
                    items, list(BUILTIN.values()), scoring=scoring, progress=False
                ),
                lambda items=items: _pixels_only(items, 16),
            )
        )
    return out
