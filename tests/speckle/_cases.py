"""Shared helpers of the speckle-filter tests: filter names and seeded test images."""

from __future__ import annotations

import torch

import torchsar as ts

NAMES = ("lee", "kuan", "enhanced_lee", "frost", "enhanced_frost", "gamma_map")
DAMPED = ("enhanced_lee", "frost", "enhanced_frost")


def call(name: str, x: torch.Tensor, *, damping: float = 1.0, **options) -> torch.Tensor:
    """Call the named filter, passing ``damping`` only to the filters that take it."""
    if name in DAMPED:
        options["damping"] = damping
    return ts.speckle.FILTERS[name](x, **options)


def speckled(shape, *, looks: float, seed: int, dtype=torch.float64) -> torch.Tensor:
    """Piecewise-constant reflectivity (random blocks, one bright point) times L-look gamma
    speckle, so all three Ci classes (homogeneous / textured / point) occur."""
    g = torch.Generator().manual_seed(seed)
    b, c, h, w = shape
    coarse = torch.rand((b, c, (h + 3) // 4, (w + 3) // 4), generator=g, dtype=torch.float64)
    refl = (0.2 + 4 * coarse).repeat_interleave(4, -2).repeat_interleave(4, -1)[..., :h, :w]
    refl = refl.clone()
    refl[..., h // 2, w // 3] *= 50.0
    gamma = torch.distributions.Gamma(torch.tensor(float(looks)), torch.tensor(float(looks)))
    torch.manual_seed(seed)
    speckle = gamma.sample((b, c, h, w)).to(torch.float64)
    return (refl * speckle).to(dtype)
