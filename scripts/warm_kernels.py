"""Compile torchsar's numba kernels ahead of use (``make setup`` runs it; see
:func:`torchsar._warm.warm`): ``python scripts/warm_kernels.py``."""

from __future__ import annotations

from torchsar._warm import warm

if __name__ == "__main__":
    print(f"torchsar: compiled kernels ready ({warm():.0f} s)")
