"""Benchmark cases for torchsar.simulate (discovered by scripts/benchmark.py).

The reference is drawing the bare clutter of the same batch (one ``torch._standard_gamma``
pass), so the ratio says how much the targets, shadows and ground truth cost on top of the
unavoidable random-number generation.
Run alone: ``PYTHONPATH=. python scripts/benchmarks/simulate.py``.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import torch

from torchsar.simulate import chips, clutter, scenes


def cases() -> list[tuple[str, Callable, Callable]]:
    """(name, ours, reference) triples."""
    return [
        (
            "chips 1000x128x128 gamma L=1",
            lambda: chips(1000, size=128),
            lambda: clutter((1000, 1, 128, 128), model="exponential"),
        ),
        (
            "chips 200x128x128 k L=4",
            lambda: chips(200, size=128, clutter="k", looks=4.0),
            lambda: clutter((200, 1, 128, 128), model="k", looks=4.0),
        ),
        (
            "scenes 4x512x512 gamma L=1",
            lambda: scenes(4, size=512),
            lambda: clutter((4, 1, 512, 512), model="exponential"),
        ),
    ]


def _time(fn: Callable, repeat: int = 3) -> float:
    fn()
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


if __name__ == "__main__":
    torch.set_num_threads(1)
    for name, ours, ref in cases():
        a, b = _time(ours), _time(ref)
        print(f"{name:32s} ours {a * 1e3:9.1f} ms  ref {b * 1e3:9.1f} ms  ratio {a / b:6.2f}")
