"""The evaluator as a Python function: :func:`evaluate` scores any detectors (built-in names,
import paths, your own callables, saved predictions) on any datasets and returns the tables;
``torchsar-eval run`` is a thin client of it.

Examples:
    >>> import torchsar_eval as te
    >>> res = te.evaluate("sim-chips", ["ca", "so"], n=4, progress=False)
    >>> res.summary[["detector", "images", "targets"]].values.tolist()
    [['ca', 4, 4], ['so', 4, 4]]
"""

from __future__ import annotations

import gc
import os
import tempfile
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import pandas as pd
from torch.utils.data import Dataset

from torchsar_eval.batches import SkipBad, TruthOnly, as_dict
from torchsar_eval.calibrate import choose_threshold, parse_target, split_indices
from torchsar_eval.datasets import make_dataset
from torchsar_eval.datasets.files import warn_shared_files
from torchsar_eval.datasets.make import MAX_N
from torchsar_eval.detector import Detector, as_detector
from torchsar_eval.errors import EvalError
from torchsar_eval.gallery import observed_facts
from torchsar_eval.html_report import DEFAULT_RANK, check_rank_by
from torchsar_eval.names import file_slugs, slug
from torchsar_eval.output import claim, result_dir, write_config
from torchsar_eval.overlays import collect_overlays, overlay_indices, parse_overlay
from torchsar_eval.registry import BUILTIN, load
from torchsar_eval.report import per_image_rows, write_run
from torchsar_eval.result import Scoring
from torchsar_eval.results import LazyTables, Results, result_tables
from torchsar_eval.resume import check_resumable, fingerprint
from torchsar_eval.settings import Calibration, Execution
from torchsar_eval.shards import ShardJob, run_shards, shard_coco, shard_ranges, shard_rows
from torchsar_eval.sweep import as_frame, choose, sweep_table, variants
from torchsar_eval.tables import PER_IMAGE_COLUMNS

__all__ = ["Results", "evaluate"]


@dataclass(frozen=True)
class _Plan:
    """Everything a run does to each dataset (validated)."""

    detectors: list[Detector]
    scoring: Scoring
    execution: Execution
    calibration: Calibration | None
    preprocess: Callable | None
    despeckle: dict | None
    window_units: str
    export_coco: bool
    seed: int
    overlay: int | tuple[str, ...] | None = None
    rank_by: str = DEFAULT_RANK
    figures: bool = True


def _datasets(datasets: object, n: int | None, seed: int) -> dict[str, Dataset]:
    """``{name: dataset}`` from a name, a dataset, a list of them or a dict."""

    if isinstance(datasets, str | Dataset):
        datasets = [datasets]
    if isinstance(datasets, Mapping):
        items = list(datasets.items())
    elif isinstance(datasets, Iterable):
        items = [(d if isinstance(d, str) else getattr(d, "name", None), d) for d in datasets]
    else:
        raise EvalError(
            f"{{opt:datasets}}{datasets!r}: expected a dataset name, a dataset or "
            "a list or dict of them"
        )
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_N):
        raise EvalError(f"{{opt:n}}{n!r}: must be an integer from 1 to {MAX_N:,}")
    out: dict[str, Dataset] = {}
    for i, (name, d) in enumerate(items):
        name = str(name) if name else f"dataset{i}"
        if name in out:
            raise EvalError(f"{{opt:datasets}} names {name!r} twice")
        out[name] = make_dataset(d, n=n, seed=seed) if isinstance(d, str) else d
    if not out:
        raise EvalError("{opt:datasets} is empty: give at least one dataset")
    warn_shared_files(out)  # one image read by two datasets is counted in both
    return out


def _detectors(detectors: object) -> list[Detector]:
    """Detectors from names / import paths, detector objects, or a list or dict of them."""

    if isinstance(detectors, str) or callable(detectors):
        detectors = [detectors]
    if isinstance(detectors, Mapping):
        items = list(detectors.items())
    elif isinstance(detectors, Iterable):
        items = [(None, d) for d in detectors]
    else:
        raise EvalError(
            f"{{opt:detectors}}{detectors!r}: expected a detector, a name or a list or dict of them"
        )
    out = [load(d, name=name) if isinstance(d, str) else as_detector(d, name) for name, d in items]
    names = [d.name for d in out]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise EvalError(
            f"{{opt:detectors}} names {', '.join(twice)} more than once: give each its own name"
        )
    if not out:
        raise EvalError("{opt:detectors} is empty: give at least one detector")
    return out


def _check_type(value: object, kind: type, name: str) -> None:
    if value is not None and not isinstance(value, kind):
        raise EvalError(
            f"{{opt:{name}}}{value!r}: expected a torchsar_eval.{kind.__name__} or None"
        )


def evaluate(
    datasets: object,
    detectors: object = None,
    *,
    scoring: Scoring | None = None,
    execution: Execution | None = None,
    calibration: Calibration | None = None,
    preprocess: Callable | None = None,
    despeckle: Mapping[str, Any] | None = None,
    window_units: str = "px",
    export_coco: bool = False,
    overlay: int | Sequence[str] | None = None,
    out: str | Path | None = None,
    figures: bool | None = None,
    overwrite: bool = False,
    resume: bool = False,
    discard: bool = False,
    n: int | None = None,
    seed: int = 0,
    progress: bool | None = None,
    rank_by: str = DEFAULT_RANK,
) -> Results:
    """Score detectors on datasets: every detector's output through the same matching,
    states, intervals and tables.

    Args:
        datasets: a dataset name (``"sim-chips"``, ``"coco:ann.json"``, ...; see
            :func:`torchsar_eval.datasets.make_dataset`), a torch ``Dataset`` yielding the
            harness's items, or a list or ``{name: dataset}`` dict of them.
        detectors: a built-in name, an entry-point name or an import path
            (``"package.module:name"``), a :class:`~torchsar_eval.Detector`, any callable
            ``images (B, C, H, W) -> Detection | Objects``, saved predictions
            (:func:`torchsar_eval.predictions`), or a list or ``{name: detector}`` dict of
            them. Default: every built-in detector.
        scoring: discrimination, matching, bootstrap and instance policy (default
            :class:`~torchsar_eval.Scoring`).
        execution: batches, shards, workers, engine, device (default
            :class:`Execution`).
        calibration: choose each detector's operating point on a calibration split.
        preprocess: an image stage run once per batch before every detector (e.g. a
            speckle filter); ``despeckle`` records its options in ``config.json``.
        window_units: ``"px"`` or ``"m"``: the detectors' ``guard`` / ``train`` options in
            metres, converted per dataset with its pixel spacing.
        export_coco: write the ground truth and detections as COCO JSON (needs ``out``).
        overlay: draw whole images with every detector's detections and the ground truth
            (``overlays/``, and in the report; needs ``out``): the first ``N`` images of
            the reported split, or the images named (name, file name or stem).
        out: the run folder to write (tables, plots, ``config.json``); ``None`` writes
            nothing. The folder is published whole or not at all.
        figures: with ``out``, draw the curves (``roc_<dataset>.png`` / ``.pdf``), the
            worst-case gallery and ``report.html``; ``False`` writes the tables,
            ``summary.md``, ``summary.tex`` and ``config.json`` only (``torchsar-eval
            report RUN`` builds the page later). Default: ``True``, or ``False`` where the
            environment variable ``TORCHSAR_EVAL_FIGURES`` is ``0`` (a test suite or a
            pipeline that reads only tables).
        overwrite: replace a previous run in ``out``.
        resume: continue the interrupted run in ``out`` from its saved shards. A run that
            fails or is interrupted keeps its saved shards (in a hidden folder beside
            ``out``) for this; a new run of the same ``out`` is refused until the saved
            work is resumed or discarded.
        discard: delete the saved work an interrupted run of ``out`` left, and start over.
        n: images per named dataset (default: the dataset's own size).
        seed: seed of the simulated datasets.
        progress: shorthand for ``execution.progress``.
        rank_by: the metric that ranks the leaderboards of the run folder's
            ``report.html`` (a ``summary.csv`` column such as ``"f1"``, ``"ap50"``,
            ``"pd_at_1_fa_per_image"``, or ``"ms_per_image"``; default F1).

    Returns:
        :class:`Results`: the tables as DataFrames, the merged states, the run statistics.

    Raises:
        EvalError: a bad option, dataset or detector, named by its parameter.
    """

    _check_type(scoring, Scoring, "scoring")
    _check_type(execution, Execution, "execution")
    _check_type(calibration, Calibration, "calibration")
    execution = execution or Execution()
    if progress is not None:
        execution = replace(execution, progress=progress)
    execution = _cap_workers(execution)
    if figures is not None and not isinstance(figures, bool):
        raise EvalError(f"{{opt:figures}}{figures!r}: expected True or False")
    if window_units not in ("px", "m"):
        raise EvalError(f"{{opt:window_units}}{window_units!r}: expected 'px' or 'm'")
    overlay = parse_overlay(overlay)
    if (resume or overwrite or discard or export_coco or overlay) and out is None:
        wanted = next(
            k
            for k, v in [
                ("resume", resume),
                ("overwrite", overwrite),
                ("discard", discard),
                ("export_coco", export_coco),
                ("overlay", True),
            ]
            if v
        )
        raise EvalError(f"{{opt:{wanted}}} needs {{opt:out}}FOLDER")
    plan = _Plan(
        detectors=_detectors(list(BUILTIN.values()) if detectors is None else detectors),
        scoring=scoring or Scoring(),
        execution=execution,
        calibration=calibration,
        preprocess=preprocess,
        despeckle=None if despeckle is None else dict(despeckle),
        window_units=window_units,
        export_coco=export_coco,
        seed=seed,
        rank_by=check_rank_by(rank_by),
        overlay=overlay,
        figures=default_figures() if figures is None else figures,
    )
    with ExitStack() as stack:
        stack.enter_context(_own_heap())
        named = _datasets(datasets, n, seed)
        if out is None:
            tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="torchsar-")))
            return _execute(plan, named, tmp, None)
        target = stack.enter_context(
            claim(Path(out), overwrite=overwrite, resume=resume, discard=discard)
        )
        tmp = stack.enter_context(result_dir(target, resume=resume, keep=True))
        results = _execute(plan, named, tmp, target)
    return results


FIGURES_ENV = "TORCHSAR_EVAL_FIGURES"
"""The environment variable whose value ``0`` turns a run's figures off by default."""


def default_figures() -> bool:
    """Whether a run draws its figures when not told (:data:`FIGURES_ENV` not ``0``)."""
    return os.environ.get(FIGURES_ENV, "1").strip().lower() not in ("0", "false", "no", "off")


@contextmanager
def _own_heap() -> Iterator[None]:
    """The garbage collections of a run scan only the run's own objects: the caller's heap
    (a training process, another evaluator's leftovers) waits in the permanent generation
    for the run (``gc.freeze``) and goes back after. Measured: a 200-image results file
    scored right after ``pycocotools`` took 55 ms, 43 ms without that heap to scan. Left
    alone when the caller freezes objects itself or has paused the collector."""
    if gc.get_freeze_count() or not gc.isenabled():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _cap_workers(ex: Execution) -> Execution:
    """More local workers than cores only adds processes and memory: capped, with a
    warning."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    cores = cores or 1
    if ex.engine == "local" and ex.workers > cores:
        warnings.warn(
            f"{ex.workers} workers are more than this machine's {cores} cores: using {cores}",
            UserWarning,
            stacklevel=3,
        )
        return replace(ex, workers=cores)
    return ex


SWEEP_FILE = "sweep.csv"
"""The settings a sweep tried (:attr:`Results.sweep`)."""


def sweep_frame(stats: dict) -> pd.DataFrame:
    """Every dataset's sweep rows (``sweep.csv``)."""

    return as_frame([row for st in stats.values() for row in st.get("sweep", {}).get("rows", [])])


def _note_idle_workers(name: str, images: int, ex: Execution) -> None:
    """One line when a dataset has fewer shards than local workers: the others stay idle
    (a shard is one worker's unit of work)."""
    shards = -(-images // ex.shard_size)
    if ex.engine == "local" and ex.workers > 1 and shards < ex.workers:
        warnings.warn(
            f"dataset {name}: {images} images make {shards} shard(s) of at most "
            f"{ex.shard_size}, so only {shards} of the {ex.workers} workers have "
            "work; a smaller --shard-size spreads it",
            UserWarning,
            stacklevel=4,
        )


def _execute(plan: _Plan, datasets: dict, tmp: Path, out: Path | None) -> Results:
    """Score every dataset into the folder ``tmp`` (a run's staging folder, or a temporary
    one); with ``out``, write the tables, plots and ``config.json`` there too."""

    if out is not None:  # a temporary folder is never resumed: nothing to record
        check_resumable(tmp / "resume.json", fingerprint(plan, datasets))
    results, stats, windows, overlays = {}, {}, {}, {}
    labels = file_slugs(datasets, slug)  # unique file names even for same-named folders
    for name, ds in datasets.items():
        dets = [_bound(d, ds, name) for d in plan.detectors]
        if plan.window_units == "m":
            dets = windows_in_pixels(name, ds, dets)
        windows[name] = {d.name: d.describe() for d in dets}
        results[name], stats[name] = evaluate_dataset(
            name, ds, dets, plan, tmp / "shards" / labels[name], persist=out is not None
        )
        overlays[name] = stats[name].pop("overlays")
        exporter = stats[name].pop("export")
        if exporter is not None:
            exporter.write(tmp / "coco", labels[name])
    tables = result_tables(results) if out is not None else LazyTables(results)
    swept = sweep_frame(stats)
    folders = {n: tmp / "shards" / labels[n] / "test" for n in results}
    files: list[str] = []
    if out is not None:
        rows = per_image_rows({n: shard_rows(f) for n, f in folders.items()})
        observed = {n: observed_facts(rs) for n, rs in results.items()}
        write_config(tmp, "run", config(plan, datasets, windows, stats, out, observed))
        if not swept.empty:  # before the report, which shows the chosen settings
            swept.to_csv(tmp / SWEEP_FILE, index=False)
        files = write_run(
            tmp,
            tables,
            rows,
            plan.scoring,
            stats,
            labels,
            results=results,
            rank_by=plan.rank_by,
            overlays=overlays,
            figures=plan.figures,
        )
        files += [SWEEP_FILE] if not swept.empty else []
        per_image = pd.read_csv(tmp / "per_image.csv")
    else:
        rows = per_image_rows({n: shard_rows(f) for n, f in folders.items()})
        per_image = pd.DataFrame(list(rows), columns=PER_IMAGE_COLUMNS)
    return Results(
        tables,
        per_image=per_image,
        states=results,
        stats=stats,
        out=out,
        files=[*files, "config.json"] if out is not None else [],
        sweep=swept,
    )


def _bound(det: Detector, ds: Dataset, name: str) -> Detector:
    """Detectors that read per-dataset files (saved predictions) bound to the dataset."""
    bind = getattr(det.fn, "bind", None)
    return det if bind is None else replace(det, fn=bind(ds, name))


def config(
    plan: _Plan, datasets: dict, windows: dict, stats: dict, out: Path, observed: dict | None = None
) -> dict:
    """The ``config.json`` record of a run (``observed``: per dataset, the image sizes and
    pixel spacings the images had)."""
    ex, cal = plan.execution, plan.calibration
    return {
        "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
        "manifests": {n: d.manifest() for n, d in datasets.items() if hasattr(d, "manifest")},
        "detectors": {d.name: d.describe() for d in plan.detectors},
        "window_units": plan.window_units,
        "detectors_in_pixels": windows,
        "despeckle": plan.despeckle,
        "scoring": plan.scoring.as_dict(),
        "workers": ex.workers,
        "engine": ex.engine,
        "device": ex.device,
        "shard_size": ex.shard_size,
        "throughput": {n: {k: v for k, v in st.items() if k != "sweep"} for n, st in stats.items()},
        "calibration": None if cal is None else cal.as_dict(),
        "sweep": {n: st["sweep"]["chosen"] for n, st in stats.items() if "sweep" in st},
        "batch_size": ex.batch_size,
        "seed": plan.seed,
        "out": str(out),
        "observed": observed or {},
        "rank_by": plan.rank_by,
        "figures": plan.figures,
    }


def windows_in_pixels(name: str, ds, detectors: list[Detector]) -> list[Detector]:
    """Detectors with ``guard`` / ``train`` given in metres converted to pixels with the
    dataset's pixel spacing (the mean of its row and column spacing, read from item 0)."""
    spacing = as_dict(ds[0])["meta"].get("pixel_spacing") if len(ds) else None
    if spacing is None:
        raise EvalError(
            f"{{opt:window_units}}'m' needs the pixel spacing of {name}: declare "
            "it with ?spacing=METRES"
        )
    step = (float(spacing[0]) + float(spacing[1])) / 2
    out = []
    for det in detectors:
        conv = {
            k: round(float(det.options[k]) / step) for k in ("guard", "train") if k in det.options
        }
        if conv.get("train", 1) < 1:
            raise EvalError(
                f"{det.name}: train {det.options['train']} m is less than one "
                f"pixel of {name} ({step:g} m)"
            )
        out.append(det.with_options(conv) if conv else det)
    return out


def _default_class(ds) -> str:
    """The class COCO-compatible scoring gives to class-agnostic detections: the dataset's
    first category (COCO files: the lowest category id), else the first class among its
    first items' ground truth, else ``"target"``."""
    known = getattr(ds, "default_class", None)
    if known is not None:
        return str(known)
    for i in range(min(len(ds), 16)):
        classes = as_dict(ds[i])["meta"].get("classes") or []
        if classes:
            return str(classes[0])
    return "target"


def _check_failures(name: str, total: int, bad: list, counts: dict, ex: Execution) -> None:
    """Refuse to publish a dataset whose images all failed, or more than ``max_bad`` of
    them (skipped items plus the images of failed shards)."""
    max_bad = ex.max_bad
    sizes = shard_ranges(total, ex.shard_size) if counts["failed"] else []
    failed = len(bad) + sum(len(sizes[f["shard"]]) for f in counts["failed"])
    if total == 0 or failed == 0:
        return
    limit = "" if max_bad is None else f" (more than {{opt:max_bad}}{max_bad:g})"
    if failed >= total or (max_bad is not None and failed > max_bad * total):
        first = (
            bad[0]
            if bad
            else (f"shard {counts['failed'][0]['shard']}", counts["failed"][0]["error"])
        )
        raise EvalError(
            f"dataset {name}: {failed} of {total} images failed{limit}, the "
            f"first {first[0]}: {first[1]}"
        )


def evaluate_dataset(
    name: str, ds, detectors: list[Detector], plan: _Plan, state: Path, persist: bool = True
):
    """Score one dataset shard by shard (their states saved in ``state`` when ``persist``,
    for a resume); with a calibration each detector's operating point
    is chosen on the calibration split and the results are the disjoint test split's.
    Returns the merged results and the dataset's run statistics: images (of the reported
    split), scored (images scored in this run, calibration split included) and reused
    (found in the saved shards of an interrupted run), wall time, throughput of the scored
    images, shards."""
    t0 = time.perf_counter()
    ex, cal = plan.execution, plan.calibration
    indices = list(range(len(ds)))
    _note_idle_workers(name, len(indices), ex)
    default_class = _default_class(ds) if plan.scoring.coco_compatible else "target"
    source = ds  # the images themselves, for overlays
    if plan.preprocess is None and not any(d.needs_images for d in detectors):
        ds = TruthOnly(ds)  # saved predictions only: no image is decoded
    if ex.skip_bad:
        ds = SkipBad(ds)

    def shards(idx: list[int], folder: Path, export: bool = False, dets=None):
        job = ShardJob(
            name,
            ds,
            idx,
            dets or detectors,
            plan.scoring,
            ex,
            plan.preprocess,
            export_coco=export,
            default_class=default_class,
        )
        return run_shards(job, folder, persist=persist or export)

    chosen, calib_counts, swept = None, {"scored_images": 0, "reused_images": 0}, None
    if cal is not None:
        target = parse_target(cal.target)
        calib, indices = split_indices(len(ds), name, cal.fraction)
        if not calib or not indices:
            raise EvalError(
                f"dataset {name} has {len(ds)} images: too few for a calibration "
                f"split of {cal.fraction:g}"
            )
        if cal.sweep is not None:  # settings chosen on the calibration split only
            detectors, chosen, swept = _swept(name, detectors, cal, target, calib, shards, state)
            calib_counts = swept.pop("counts")
        else:
            tuned, calib_counts = shards(calib, state / "calibration")
            chosen = [choose_threshold(r.objects, target) for r in tuned]
    to_draw = []  # checked before the run: a name that is not there stops it now
    if plan.overlay and persist:
        to_draw = overlay_indices(source, plan.overlay, indices, name)
    results, counts = shards(indices, state / "test", plan.export_coco)
    for r, det in zip(results, detectors, strict=True):
        r.detector = det  # saved shards keep only its name
    exporter = shard_coco(state / "test", name) if plan.export_coco else None
    for r, t in zip(results, chosen or [], strict=False):
        if t is not DESIGN:  # a swept detector reports at its chosen setting's design point
            r.choose(t)
    drawn = collect_overlays(
        name,
        source,
        results,
        to_draw,
        plan.scoring,
        preprocess=plan.preprocess,
        device=ex.device,
        default_class=default_class,
    )
    wall = time.perf_counter() - t0
    bad = results[0].skipped if results else []
    _check_failures(name, len(indices), bad, counts, ex)
    scored = counts.pop("scored_images") + calib_counts["scored_images"]
    reused = counts.pop("reused_images") + calib_counts["reused_images"]
    stats = {
        "images": len(indices),
        "scored": scored,
        "reused": reused,
        "wall_s": wall,
        **counts,
        "export": exporter,
        "overlays": drawn,
        "skipped_items": [{"file": f, "error": e} for f, e in bad],
        "images_per_s": scored / wall if scored and wall > 0 else float("nan"),
    }
    if swept is not None:
        stats["sweep"] = swept
    return results, stats


DESIGN = object()
"""A swept detector's operating point: its chosen setting's design threshold."""


def _swept(
    name: str,
    detectors: list[Detector],
    cal: Calibration,
    target,
    calib: list[int],
    shards,
    state: Path,
) -> tuple[list[Detector], list, dict]:
    """Every detector's variants over the sweep scored on the calibration split (one pass),
    each detector's best variant, the calibrated thresholds of the detectors without a
    swept option, and the sweep's record: ``{"rows": sweep.csv rows, "chosen": {detector:
    options}, "counts"}``."""

    tried = [variants(d, cal.sweep) for d in detectors]
    if not any(tried):
        raise EvalError(
            f"{{opt:sweep}} names no option of any detector of this run: {', '.join(cal.sweep)}"
        )
    flat = [v for vs, d in zip(tried, detectors, strict=True) for v in (vs or [d])]
    tuned, counts = shards(calib, state / "calibration", dets=flat)
    final, thresholds, rows, picked, k = [], [], [], {}, 0
    for det, vs in zip(detectors, tried, strict=True):
        if not vs:
            final.append(det)
            thresholds.append(choose_threshold(tuned[k].objects, target))
            k += 1
            continue
        keys = [o for o in cal.sweep if det.has_option(o)]
        index, settings = choose(vs, tuned[k : k + len(vs)], target, keys)
        k += len(vs)
        rows += sweep_table(name, settings, index, target)
        picked[det.name] = settings[index].options
        final.append(replace(vs[index], name=det.name))
        thresholds.append(DESIGN)
    return final, thresholds, {"rows": rows, "chosen": picked, "counts": counts}
