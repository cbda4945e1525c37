"""False-alarm calibration: measured Pfa of detectors on homogeneous simulated clutter.

Pure functions (no I/O): :func:`binomial_interval` and :func:`measure` build the rows of
``torchsar-eval pfa``'s table; :data:`CLUTTER` lists the clutter models it uses.
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd
from scipy import stats
from torch import Tensor

from torchsar_eval.detector import Detector

__all__ = [
    "CLUTTER",
    "PFA_COLUMNS",
    "ClutterCase",
    "binomial_interval",
    "measure",
    "measure_dataset",
]


@dataclass(frozen=True)
class ClutterCase:
    """One homogeneous clutter model of :func:`torchsar.simulate.clutter` (unit mean)."""

    name: str
    model: str
    looks: float = 1.0
    shape_param: float | None = None

    def sample(self, n: int, size: int, seed: int) -> Tensor:
        """``(n, 1, size, size)`` float32 clutter, seeded."""
        from torchsar.simulate import clutter

        return clutter(
            (n, 1, size, size),
            model=self.model,
            looks=self.looks,
            shape_param=self.shape_param,
            seed=seed,
        )


CLUTTER = (
    ClutterCase("exponential", "exponential"),
    ClutterCase("gamma L=4", "gamma", looks=4.0),
    ClutterCase("K nu=2", "k", shape_param=2.0),
    ClutterCase("G0 a=3", "g0", shape_param=3.0),
    ClutterCase("lognormal s=1", "lognormal", shape_param=1.0),
    ClutterCase("Weibull c=0.8", "weibull", shape_param=0.8),
)
"""The models of the calibration table: the simulator's defaults, 4 looks for gamma."""

PFA_COLUMNS = [
    "detector",
    "clutter",
    "model",
    "looks",
    "shape_param",
    "design_pfa",
    "measured_pfa",
    "ci_low",
    "ci_high",
    "false_alarms",
    "pixels",
    "ratio",
    "design_in_ci",
]


def binomial_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Clopper-Pearson (exact) interval of a binomial rate ``k / n``.

    Examples:
        >>> lo, hi = binomial_interval(10, 10_000)
        >>> round(lo, 5), round(hi, 5)
        (0.00048, 0.00184)
    """
    a = (1.0 - level) / 2.0
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1.0 - a, k + 1, n - k))
    return lo, hi


def _params_for(spec: Detector, case: ClutterCase, pfa: float) -> Detector:
    """The detector at design ``pfa``; a detector with a ``looks`` option gets the clutter's."""
    over: dict[str, object] = {"pfa": pfa}
    if "looks" in inspect.signature(spec.fn).parameters:
        over["looks"] = case.looks
    return spec.with_options(over)


def measure(
    specs: Sequence[Detector], case: ClutterCase, x: Tensor, pfas: Sequence[float]
) -> pd.DataFrame:
    """Measured Pfa of every detector at every design ``pfa`` on clutter ``x`` (every pixel
    counted; the interval treats pixels as independent trials, which neighbouring windows
    are not quite)."""
    rows = []
    for spec in specs:
        for pfa in pfas:
            det = _params_for(spec, case, pfa)(x)
            k, n = int(det.mask.sum()), det.mask.numel()
            lo, hi = binomial_interval(k, n)
            rows.append(
                [
                    spec.name,
                    case.name,
                    case.model,
                    case.looks,
                    case.shape_param,
                    pfa,
                    k / n,
                    lo,
                    hi,
                    k,
                    n,
                    (k / n) / pfa,
                    lo <= pfa <= hi,
                ]
            )
    return pd.DataFrame(rows, columns=PFA_COLUMNS)


def measure_dataset(
    specs: Sequence[Detector], name: str, dataset, pfas: Sequence[float], batch_size: int
) -> pd.DataFrame:
    """Measured Pfa of every detector at every design ``pfa`` on a dataset's clutter pixels
    (neither target nor ignore): how far real clutter is from the detectors' models."""
    from torchsar_eval.batches import batches

    counts = {(s.name, p): [0, 0] for s in specs for p in pfas}
    for batch in batches(dataset, batch_size):
        clutter = ~batch["mask"] & ~batch["ignore"]
        for spec in specs:
            for pfa in pfas:
                det = spec.with_options({"pfa": pfa})(batch["image"])
                c = counts[(spec.name, pfa)]
                c[0] += int((det.mask & clutter).sum())
                c[1] += int(clutter.sum())
    rows = []
    for (det, pfa), (k, n) in counts.items():
        lo, hi = binomial_interval(k, n) if n else (float("nan"), float("nan"))
        rate = k / n if n else float("nan")
        rows.append(
            [
                det,
                name,
                "real clutter",
                float("nan"),
                None,
                pfa,
                rate,
                lo,
                hi,
                k,
                n,
                rate / pfa,
                lo <= pfa <= hi,
            ]
        )
    return pd.DataFrame(rows, columns=PFA_COLUMNS)
