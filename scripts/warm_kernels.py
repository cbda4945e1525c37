"""Compile torchsar's numba kernels ahead of use (``make setup`` runs it; see
:func:`torchsar._warm.warm`) and compute the K / G0 CFARs' default design tables into
their on-disk cache (:func:`torchsar._warm.warm_tables`): ``python scripts/warm_kernels.py``."""

from __future__ import annotations

from torchsar._warm import warm, warm_tables

if __name__ == "__main__":
    print(f"torchsar: compiled kernels ready ({warm():.0f} s)")
    print(f"torchsar: K and G0 design tables cached ({warm_tables():.0f} s)")
