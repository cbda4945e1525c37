"""A run's ``config.json`` as typed records: every field the report, the leaderboards and
``summary.md`` read, parsed once, here, and defensively. Older runs lack fields and newer
ones add some; a hand-edited file may hold anything: a missing or malformed field becomes
``None`` or empty, never a ``KeyError`` or ``AttributeError`` deep inside a page.

Examples:
    >>> rec = run_record({"time": "2026-01-01", "options": {
    ...     "datasets": {"chips": {"scheme": "sim", "sample_type": "display"}},
    ...     "throughput": {"chips": {"wall_s": 2.5, "images_per_s": 4}},
    ...     "calibration": {"fraction": 0.3, "target": "f1", "sweep": None}}})
    >>> rec.dataset("chips").sample_type, rec.dataset("chips").wall_s
    ('display', 2.5)
    >>> rec.dataset("elsewhere").scheme is None, rec.calibration.target, rec.calibration.sweep
    (True, 'f1', {})
    >>> run_record({"options": "not a mapping"}).matching is None
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "Bootstrap",
    "Calibration",
    "DatasetRecord",
    "Matching",
    "ObjectRules",
    "RunRecord",
    "run_record",
]


def _map(value: object) -> dict:
    return value if isinstance(value, dict) else {}


def _list(value: object) -> list:
    return value if isinstance(value, list) else []


def _text(value: object) -> str | None:
    return str(value) if isinstance(value, str | int | float) and str(value) else None


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


@dataclass(frozen=True)
class DatasetRecord:
    """What a run recorded of one dataset: its options (``scheme``, ``root``,
    ``sample_type``, declared ``pixel_spacing``, ``gt``, ``instances``), its manifest
    (``generator``, ``files``), what its images were (``image_sizes``, ``spacings``), its
    throughput (``wall_s``, ``images_per_s``, ``failed`` shards, ``skipped_items``) and the
    settings a sweep chose per detector (``chosen``)."""

    scheme: str | None = None
    root: str | None = None
    sample_type: str | None = None
    pixel_spacing: object = None
    gt: str | None = None
    instances: str | None = None
    generator: str | None = None
    files: int | None = None
    image_sizes: list = field(default_factory=list)
    spacings: list = field(default_factory=list)
    wall_s: float | None = None
    images_per_s: float | None = None
    failed: list = field(default_factory=list)
    skipped_items: list = field(default_factory=list)
    chosen: dict = field(default_factory=dict)

    @property
    def source(self) -> str | None:
        """Where the images came from: the simulator or the folder read."""
        return self.generator or self.root


@dataclass(frozen=True)
class Matching:
    """The matching rule: ``kind``, and for distance rules ``max_distance`` in
    ``distance_units``; ``fields`` is the whole record (the rule's words are filled from
    it)."""

    kind: str | None
    max_distance: float | None
    distance_units: str
    fields: dict


@dataclass(frozen=True)
class ObjectRules:
    """The discrimination stage: morphological ``closing`` (px), component ``floor`` (a
    share of the threshold), ``min_area`` in ``units``."""

    closing: object
    floor: float
    min_area: float | None
    units: str


@dataclass(frozen=True)
class Bootstrap:
    """The bootstrap behind the intervals: ``replicates`` (``None`` or 0: off)."""

    replicates: int | None


@dataclass(frozen=True)
class Calibration:
    """An operating point chosen on a calibration split: its ``fraction`` of the images,
    its ``target`` (``f1`` or ``fa=L``) and the ``sweep`` grid (empty: threshold only)."""

    fraction: object
    target: str | None
    sweep: dict


@dataclass(frozen=True)
class RunRecord:
    """A run's ``config.json``, typed (see :func:`run_record`)."""

    datasets: dict[str, DatasetRecord] = field(default_factory=dict)
    detectors: dict[str, dict] = field(default_factory=dict)
    matching: Matching | None = None
    objects: ObjectRules | None = None
    bootstrap: Bootstrap | None = None
    calibration: Calibration | None = None
    despeckle: dict = field(default_factory=dict)
    rank_by: str | None = None
    out: str | None = None
    time: str | None = None
    torchsar_version: str | None = None
    torch_version: str | None = None

    def dataset(self, name: str) -> DatasetRecord:
        """The record of dataset ``name`` (an empty one when the run holds none)."""
        return self.datasets.get(name) or DatasetRecord()

    def detector_options(self, dataset: str, detector: str) -> dict:
        """A detector's options as the run applied them on ``dataset``: those recorded,
        then the settings a sweep chose over them."""
        return {
            **self.detectors.get(detector, {}),
            **self.dataset(dataset).chosen.get(detector, {}),
        }


def _dataset(name: str, opts: dict) -> DatasetRecord:
    ds = _map(_map(opts.get("datasets")).get(name))
    manifest = _map(_map(opts.get("manifests")).get(name))
    observed = _map(_map(opts.get("observed")).get(name))
    thr = _map(_map(opts.get("throughput")).get(name))
    files = manifest.get("files")
    chosen = _map(_map(opts.get("sweep")).get(name))
    return DatasetRecord(
        scheme=_text(ds.get("scheme")),
        root=_text(ds.get("root")),
        sample_type=_text(ds.get("sample_type")),
        pixel_spacing=ds.get("pixel_spacing") or None,
        gt=_text(ds.get("gt")),
        instances=_text(ds.get("instances")),
        generator=_text(manifest.get("generator")),
        files=files if isinstance(files, int) and not isinstance(files, bool) else None,
        image_sizes=_list(observed.get("image_size")),
        spacings=_list(observed.get("pixel_spacing")),
        wall_s=_number(thr.get("wall_s")),
        images_per_s=_number(thr.get("images_per_s")),
        failed=_list(thr.get("failed")),
        skipped_items=_list(thr.get("skipped_items")),
        chosen={k: _map(v) for k, v in chosen.items()},
    )


def _matching(scoring: dict) -> Matching | None:
    match = _map(scoring.get("matching"))
    if not match:
        return None
    return Matching(
        kind=_text(match.get("kind")),
        max_distance=_number(match.get("max_distance")),
        distance_units=_text(match.get("distance_units")) or "",
        fields=match,
    )


def _objects(scoring: dict) -> ObjectRules | None:
    rules = _map(scoring.get("objects"))
    if not rules:
        return None
    floor = _number(rules.get("floor", 1))
    return ObjectRules(
        closing=rules.get("closing"),
        floor=1.0 if floor is None else floor,
        min_area=_number(rules.get("min_area")),
        units=_text(rules.get("units")) or "px",
    )


def _calibration(opts: dict) -> Calibration | None:
    cal = opts.get("calibration")
    if not isinstance(cal, dict):
        return None
    return Calibration(
        fraction=cal.get("fraction"), target=_text(cal.get("target")), sweep=_map(cal.get("sweep"))
    )


def run_record(config: Any) -> RunRecord:
    """The typed record of a ``config.json`` document (anything: a missing or broken
    file reads as ``{}``, an empty record)."""
    config = _map(config)
    opts = _map(config.get("options"))
    scoring = _map(opts.get("scoring"))
    names = {
        *_map(opts.get("datasets")),
        *_map(opts.get("manifests")),
        *_map(opts.get("observed")),
        *_map(opts.get("throughput")),
        *_map(opts.get("sweep")),
    }
    boot = _map(scoring.get("bootstrap"))
    replicates = boot.get("replicates")
    return RunRecord(
        datasets={str(n): _dataset(n, opts) for n in names},
        detectors={str(k): _map(v) for k, v in _map(opts.get("detectors")).items()},
        matching=_matching(scoring),
        objects=_objects(scoring),
        bootstrap=Bootstrap(replicates if isinstance(replicates, int) else None) if boot else None,
        calibration=_calibration(opts),
        despeckle=_map(opts.get("despeckle")),
        rank_by=_text(opts.get("rank_by")),
        out=_text(opts.get("out")),
        time=_text(config.get("time")),
        torchsar_version=_text(config.get("torchsar_version")),
        torch_version=_text(config.get("torch_version")),
    )
