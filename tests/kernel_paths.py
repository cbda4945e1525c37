"""Running a call with the compiled kernels and without them (``torchsar._jit.ENABLED``),
and comparing what the two paths give."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchsar import _jit


def both(monkeypatch, fn) -> list:
    """``fn()`` with the kernels on, then off."""
    out = []
    for on in (True, False):
        monkeypatch.setattr(_jit, "ENABLED", on)
        out.append(fn())
    return out


class _RulesOff:
    """``torchsar._jit`` as a detector module sees it with its compiled code off: every
    attribute the module's, but no tensor is for the kernels."""

    def __getattr__(self, name: str):
        return getattr(_jit, name)

    @staticmethod
    def for_tensor(_t) -> bool:
        return False


def rules_both(monkeypatch, fn, modules) -> list:
    """``fn()`` with the kernels on, then with the kernels off in ``modules`` only (the
    detectors' compiled rules and one-sweep kernels), still on for the window sums
    (:func:`torchsar.windows.windowed`): both runs read the same sums."""
    monkeypatch.setattr(_jit, "ENABLED", True)
    out = [fn()]
    with monkeypatch.context() as m:
        for module in modules:
            m.setattr(module, "_jit", _RulesOff())
        out.append(fn())
    return out


def errors(monkeypatch, call) -> list[tuple[type, str]]:
    """The error ``call`` raises with the kernels on, then off (type and words)."""
    out = []
    for on in (True, False):
        monkeypatch.setattr(_jit, "ENABLED", on)
        with pytest.raises(Exception) as err:
            call()
        out.append((type(err.value), str(err.value)))
    return out


def ulps(a: torch.Tensor, b: torch.Tensor) -> float:
    """Largest difference in units of the last place of ``b`` (finite entries; the
    non-finite ones must be equal)."""
    a64, b64 = a.double().numpy(), b.double().numpy()
    fin = np.isfinite(b64)
    assert np.array_equal(a64[~fin], b64[~fin])
    spacing = np.spacing(np.abs(b.numpy()[fin])).astype(np.float64)
    spacing = np.maximum(spacing, np.finfo(b.numpy().dtype).smallest_subnormal)
    return float((np.abs(a64[fin] - b64[fin]) / spacing).max(initial=0.0))
