"""Compile torchsar's numba kernels ahead of use (``make setup`` runs it; see
:func:`torchsar._warm.warm`) and compute the K / G0 CFARs' default design tables into
their on-disk cache (:func:`torchsar._warm.warm_tables`): ``python scripts/warm_kernels.py
[--workers N]``, by default one worker process per core, at most 8 (each holds torch and
numba's compiler: about half a GB)."""

from __future__ import annotations

import argparse
import os

from torchsar._warm import warm, warm_tables

if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--workers", type=int, default=min(os.cpu_count() or 1, 8), help="processes")
    args = p.parse_args()
    print(f"torchsar: compiled kernels ready ({warm(workers=args.workers):.0f} s)")
    print(f"torchsar: K and G0 design tables cached ({warm_tables():.0f} s)")
