"""The names and defaults the command line offers, without importing torch.

The parsers of ``torchsar-eval`` need only these values (for ``choices``, defaults and help
texts), so ``torchsar-eval --help`` starts without torch, pandas or matplotlib. Each value
mirrors a live one in a heavy module (the detector registry, the dataset readers, the speckle
filters, the scoring defaults); the tests check that they stay equal.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

__all__ = [
    "AUTOFOCUS_DEFAULTS",
    "AUTOFOCUS_ERRORS",
    "AUTOFOCUS_METHODS",
    "BUILTIN_DETECTORS",
    "BUILTIN_ORDER",
    "DATASET_SCHEMES",
    "DEFAULT_AUTOFOCUS_METHODS",
    "DEFAULT_CLOSING",
    "DEFAULT_MATCH_KIND",
    "DEFAULT_MAX_AREA",
    "DEFAULT_MIN_AREA",
    "DEFAULT_RANK",
    "RANK_METRICS",
    "REPORT_FILE",
    "SPECKLE_FILTERS",
    "detector_names",
]


def _declared() -> dict[str, int]:
    """The built-in detectors' names and orders as their modules declare them (each
    module's ``SPEC = DetectorSpec(name=..., order=...)``, read from the source: no import
    of torch), in order."""
    root = Path(importlib.util.find_spec("torchsar").origin).parent
    found: dict[str, int] = {}
    for package in ("cfar", "region"):
        for path in sorted((root / package).glob("*.py")):
            text = path.read_text()
            at = text.find("\nSPEC = DetectorSpec(")
            if at < 0:
                continue
            end = text.find(")\n", at)
            call = ast.parse(text[at + 1 : end + 1]).body[0].value  # the statement only
            kw = {k.arg: k.value for k in call.keywords}
            found[ast.literal_eval(kw["name"])] = ast.literal_eval(kw["order"])
    return dict(sorted(found.items(), key=lambda item: item[1]))


BUILTIN_ORDER = _declared()
"""Each built-in detector's position in the default run (and colour slot)."""
BUILTIN_DETECTORS = tuple(BUILTIN_ORDER)
"""The built-in detectors, in the registry's order (``torchsar_eval.registry.BUILTIN``)."""

DATASET_SCHEMES = (
    "sim-chips",
    "sim-scenes",
    "folder:PATH",
    "coco:FILE.json",
    "voc:DIR",
    "hrsid:DIR",
    "phoenix:DIR",
    "sicd:FILE",
    "scene:FILE",
    "store:DIR",
)
"""The dataset names and schemes ``make_dataset`` reads (``torchsar_eval.datasets.DATASETS``)."""

SPECKLE_FILTERS = ("lee", "kuan", "enhanced_lee", "frost", "enhanced_frost", "gamma_map")
"""The speckle filters by name (``torchsar.speckle.FILTERS``)."""

DEFAULT_CLOSING = 2
DEFAULT_MIN_AREA = 5.0
DEFAULT_MAX_AREA = None
"""The default object rules (``torchsar_eval.result.DEFAULT_RULES``)."""
DEFAULT_MATCH_KIND = "centroid"
"""The default matching rule (``torchsar_eval.result.DEFAULT_MATCH``)."""

AUTOFOCUS_ERRORS = ("1d-uniform-pi", "1d-quadratic-2pi", "2d-separable-3pi/4", "2d-3pi/4", "2d-pi")
"""The phase-error types of the autofocus experiment (its ``ERROR_CASES``)."""
AUTOFOCUS_METHODS = (
    "conventional",
    "lp",
    "pga",
    "min-entropy",
    "sparse-autofocus",
    "sparse-keep-restarts",
    "sparse-true-phase",
)
"""The imaging methods of the autofocus experiment (its ``METHODS``)."""
DEFAULT_AUTOFOCUS_METHODS = tuple(m for m in AUTOFOCUS_METHODS if m != "sparse-keep-restarts")
AUTOFOCUS_DEFAULTS = {
    "scenes": 10,
    "size": 64,
    "density": 0.02,
    "snr_db": 30.0,
    "seed": 0,
    "pfa": 1e-3,
}
"""The command-line defaults of the autofocus experiment (its ``Config``)."""


def detector_names() -> list[str]:
    """Every detector name: the built-ins, then the names installed packages register in
    the ``torchsar.detectors`` entry-point group (sorted), as ``registry.available()``."""
    # installed packages' entry points read only when asked (this module stays light for --help)
    from importlib.metadata import entry_points

    registered = {ep.name for ep in entry_points(group="torchsar.detectors")}
    return [*BUILTIN_DETECTORS, *sorted(registered - set(BUILTIN_DETECTORS))]


DEFAULT_RANK = "f1"
"""The metric that ranks the leaderboards of ``report.html`` unless told otherwise."""
RANK_METRICS = (
    "f1",
    "precision",
    "recall",
    "ap50",
    "ap50_95",
    "pd_at_0.1_fa_per_image",
    "pd_at_1_fa_per_image",
    "pd_at_10_fa_per_image",
    "pauc",
    "fom",
    "mean_iou",
    "pd_object",
    "pd_pixel",
    "pfa_pixel",
    "false_alarms_per_image",
    "fa_per_km2",
    "false_alarms",
    "tp",
    "fp",
    "fn",
    "fragmentation",
    "length_score",
    "ms_per_image",
    "images_per_s",
)
"""Metrics a leaderboard can be ranked by (``summary.csv`` and ``timing.csv`` columns)."""
REPORT_FILE = "report.html"
"""The report's file name in a run folder."""
