"""Benchmark cases for torchsar.simulate (discovered by scripts/benchmark.py).

The reference is drawing the bare clutter of the same batch (one ``torch._standard_gamma``
pass), so the ratio says how much the targets, shadows and ground truth cost on top of the
unavoidable random-number generation.
Run: ``python scripts/benchmark.py --topic simulate``.
"""

from __future__ import annotations

from collections.abc import Callable

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
            lambda: chips(200, size=128, model="k", looks=4.0),
            lambda: clutter((200, 1, 128, 128), model="k", looks=4.0),
        ),
        (
            "scenes 4x512x512 gamma L=1",
            lambda: scenes(4, size=512),
            lambda: clutter((4, 1, 512, 512), model="exponential"),
        ),
    ]
