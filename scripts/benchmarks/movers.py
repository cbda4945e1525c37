"""Benchmark case for torchsar.motion.find_movers: one batched call against a loop of scenes.

Twelve random 256 x 512 Table-1 scenes (6-10 stationary scatterers over a 15 dB span, one or
two along-track movers, a folded range mover in every other scene, 28 dB image peak SNR),
built with the public API (scenes of unequal sizes in one simulator call, noise at an image
peak SNR). ``find_movers`` on the batch is compared with calling it once per scene: every
per-target step (focus bank, looks, registration, verdict) is batched over the scenes.

Run: ``python scripts/benchmark.py --topic movers`` (1 thread).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable

import torch

from torchsar.motion import SpotlightParams, find_movers
from torchsar.sar import add_noise, image_noise_std, simulate_phase_history


def _scene(gen: torch.Generator, index: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    n = int(torch.randint(6, 11, (1,), generator=gen)) + 1 + (index % 2)
    pos = (torch.rand(n, 2, generator=gen, dtype=torch.float64) * 2 - 1) * torch.tensor(
        [75.0, 40.0], dtype=torch.float64
    )
    vel = torch.zeros(n, 2, dtype=torch.float64)
    vel[-1, 1] = 2 + 8 * float(torch.rand(1, generator=gen))  # along track
    if index % 2:
        vel[-2, 0] = 4.0  # folded once or twice, depending on the azimuth
    amp = torch.polar(
        10 ** (15 * torch.rand(n, generator=gen, dtype=torch.float64) / 20),
        2 * math.pi * torch.rand(n, generator=gen, dtype=torch.float64),
    )
    return pos, vel, amp


def _movers_case():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        params = SpotlightParams.from_system(image_size=(256, 512))
    gen = torch.Generator().manual_seed(0)
    pos, vel, amp = zip(*[_scene(gen, i) for i in range(12)], strict=True)
    g = simulate_phase_history(
        list(pos), params.geometry, velocities=list(vel), amplitudes=list(amp)
    )
    g = add_noise(g, std=image_noise_std(params.geometry, 28.0), seed=0).to(torch.complex64)

    def one_at_a_time():
        return [find_movers(g[i : i + 1], params, subpatch=False) for i in range(12)]

    return (
        "find_movers 12 scenes 256x512 batched vs one scene at a time",
        lambda: find_movers(g, params, subpatch=False),
        one_at_a_time,
    )


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    return [_movers_case()]
