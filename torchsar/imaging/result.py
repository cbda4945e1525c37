"""The result type family of the autofocus methods: one base, subclasses that only add fields.

Every autofocus method returns an :class:`AutofocusResult` (the corrected complex ``image``,
the estimated ``phase`` error and the ``iterations`` used); methods with an objective report
it in a subclass: :class:`SparseAutofocusResult` (cost, its history and ``lam``) and
:class:`MinEntropyResult` (the final ``entropy``). Phase convention throughout:
``g = exp(1j phase) C f``, so ``apply_phase_error(g, -result.phase)`` corrects the data.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TypeVar

from torch import Tensor

from torchsar.imaging.items import fill_items

__all__ = ["AutofocusResult", "MinEntropyResult", "SparseAutofocusResult", "fill_result"]


@dataclass(frozen=True)
class AutofocusResult:
    """Output of an autofocus method (:func:`pga`, :func:`pulse_autofocus`, and the base of
    the other results).

    Attributes:
        image: corrected complex image ``(B, 1, H, W)``.
        phase: phase-error estimate, ``(B, M)`` per pulse (1-D) or ``(B, M, K)`` (2-D).
        iterations: iterations used per item, int64 ``(B,)``.
    """

    image: Tensor
    phase: Tensor
    iterations: Tensor


@dataclass(frozen=True)
class SparseAutofocusResult(AutofocusResult):
    """Output of :func:`sparse_autofocus`: the base fields and the sparsity objective.

    Attributes:
        cost: final cost ``J`` per item ``(B,)``.
        history: cost per iteration ``(B, max_iter + 1)`` (padded after an item stopped).
        lam: regularisation weight used per item ``(B,)``.
    """

    cost: Tensor
    history: Tensor
    lam: Tensor


@dataclass(frozen=True)
class MinEntropyResult(AutofocusResult):
    """Output of the minimum-entropy methods: the base fields and the final ``entropy``
    ``(B,)`` of the corrected image intensity. ``iterations`` counts L-BFGS iterations,
    shared by the items of one call (they share the line search)."""

    entropy: Tensor


R = TypeVar("R", bound=AutofocusResult)


def fill_result(live: Tensor, part: R) -> R:
    """A result for the ``live`` items put back into the full batch (zeros elsewhere).

    Examples:
        >>> import torch
        >>> part = AutofocusResult(torch.ones(1, 1, 2, 2), torch.ones(1, 3), torch.tensor([2]))
        >>> fill_result(torch.tensor([False, True]), part).phase.tolist()
        [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]
    """
    fields = {f.name: fill_items(live, getattr(part, f.name)) for f in dataclasses.fields(part)}
    return dataclasses.replace(part, **fields)
