"""Result tables (pandas): the run summary, breakdowns, per-image rows and the curves."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from torchsar.metrics.error_types import FA_TYPES
from torchsar.metrics.object_state import ratios
from torchsar.metrics.paired import PAIRED_METRICS, difference_intervals, side

if TYPE_CHECKING:  # the tables read the states; they never build one
    from torchsar_eval.result import DetectorResult

__all__ = [
    "BREAKDOWN_COLUMNS",
    "COCO_COLUMNS",
    "COCO_STATS",
    "CONSOLE_COLUMNS",
    "ERRORS_COLUMNS",
    "FROC_COLUMNS",
    "PAIRED_COLUMNS",
    "PER_IMAGE_COLUMNS",
    "PR_COLUMNS",
    "SCR_COLUMNS",
    "SUMMARY_COLUMNS",
    "TIMING_COLUMNS",
    "breakdown_table",
    "coco_table",
    "errors_table",
    "froc_table",
    "headline_table",
    "markdown",
    "paired_table",
    "per_image_table",
    "pixel_roc_table",
    "pooled_pr",
    "pr_table",
    "scr_table",
    "summary_table",
    "timing_table",
]

HEADLINE = ["precision", "recall", "f1", "ap50", "pd_at_1_fa_per_image"]
INTERVALS = [
    *HEADLINE,
    "false_alarms_per_image",
    "fa_per_km2",
    "fom",
    "ap50_95",
    "pd_at_0.1_fa_per_image",
    "pd_at_10_fa_per_image",
    "pauc",
    "ap_distance",
]
"""The summary columns with ``_lo`` / ``_hi`` bounds (NaN with the reason in
``interval_note`` where there is none)."""
_STATE_NAME = {"false_alarms_per_image": "fa_per_image"}
SUMMARY_COLUMNS = [
    "dataset",
    "detector",
    "images",
    "targets",
    "pd_pixel",
    "pfa_pixel",
    "pd_object",
    "false_alarms",
    "false_alarms_per_image",
    "fragmentation",
    "fom",
    "mean_iou",
    "tp",
    "fp",
    "fn",
    "precision",
    "recall",
    "f1",
    "ap50",
    "ap50_95",
    "ap_small",
    "ap_medium",
    "ap_large",
    "ap_distance",
    "classes",
    "iou_type",
    "matching",
    "pd_at_0.1_fa_per_image",
    "pd_at_1_fa_per_image",
    "pd_at_10_fa_per_image",
    "pauc",
    "fa_per_km2",
    "length_score",
    *[f"{m}_{end}" for m in INTERVALS for end in ("lo", "hi")],
    "interval_note",
    "score_threshold",
]
CONSOLE_COLUMNS = [
    "dataset",
    "detector",
    "images",
    "pd_pixel",
    "pfa_pixel",
    "tp",
    "fp",
    "fn",
    "precision",
    "recall",
    "f1",
    "ap50",
    "pd_at_1_fa_per_image",
    "false_alarms_per_image",
    "mean_iou",
    "ms_per_image",
]
"""What ``torchsar-eval run`` prints (summary and timing columns)."""
TIMING_COLUMNS = [
    "dataset",
    "detector",
    "images",
    "ms_per_image",
    "object_ms_per_image",
    "images_per_s",
]
FROC_COLUMNS = [
    "dataset",
    "detector",
    "threshold",
    "tp",
    "fp",
    "false_alarms_per_image",
    "pd_object",
    "precision",
]
PR_COLUMNS = ["dataset", "detector", "class", "threshold", "recall", "precision"]
BREAKDOWN_COLUMNS = [
    "dataset",
    "detector",
    "by",
    "key",
    "images",
    "targets",
    "tp",
    "fp",
    "fn",
    "precision",
    "recall",
    "f1",
    "ap50",
    "ap50_95",
]
COCO_STATS = [
    "AP",
    "AP50",
    "AP75",
    "AP_small",
    "AP_medium",
    "AP_large",
    "AR1",
    "AR10",
    "AR100",
    "AR_small",
    "AR_medium",
    "AR_large",
]
"""``COCOeval.stats`` in order (-1 where pycocotools gives -1: nothing to average)."""
COCO_COLUMNS = ["dataset", "detector", "iou_type", *COCO_STATS]
PER_IMAGE_COLUMNS = [
    "dataset",
    "detector",
    "image",
    "targets",
    "tp",
    "fp",
    "fn",
    "objects",
    "max_score",
]
SCR_COLUMNS = [
    "dataset",
    "detector",
    "source",
    "scr_bin",
    "scr_lo_db",
    "scr_hi_db",
    "scr_mean_db",
    "targets",
    "detected",
    "pd",
    "pd_lo",
    "pd_hi",
]
ERRORS_COLUMNS = ["dataset", "detector", "error", "type", "count"]
PAIRED_COLUMNS = [
    "dataset",
    "detector",
    "reference",
    "metric",
    "difference",
    "lo",
    "hi",
    "significant",
]


def summary_row(dataset: str, r: DetectorResult) -> dict:
    """One summary row at the detector's operating point (its design or calibrated one)."""
    m = r.objects.metrics(r.threshold)
    ci = r.objects.intervals(r.threshold) if r.objects.replicates else {}
    nan = float("nan")
    if r.scoring.matching.kind == "distance":
        m["mean_iou"] = nan  # no IoU under the distance rule
    row = {
        "dataset": dataset,
        "detector": r.detector.name,
        "images": r.images,
        "targets": r.objects.n_gt,
        "pd_pixel": r.pixels.pd if r.pixel_level else nan,
        "pfa_pixel": r.pixels.pfa if r.pixel_level else nan,
        "pd_object": m["recall"],
        "false_alarms": m["fp"],
        "false_alarms_per_image": m["fa_per_image"],
        **{k: m[k] for k in SUMMARY_COLUMNS if k in m},
        "score_threshold": -np.inf if r.threshold is None else r.threshold,
        "classes": "per-class" if r.objects.by_class else "agnostic",
        "iou_type": r.iou_type,
        "matching": r.scoring.matching.describe(r.iou_type),
    }
    for k in INTERVALS:
        iv = ci.get(_STATE_NAME.get(k, k))
        row[f"{k}_lo"], row[f"{k}_hi"] = (nan, nan) if iv is None else (iv.lo, iv.hi)
    if r.scoring.matching.kind == "distance":  # AP at the distance tolerance: not at IoU 0.5
        for end in ("", "_lo", "_hi"):
            row[f"ap_distance{end}"], row[f"ap50{end}"] = row[f"ap50{end}"], nan
    else:
        row["ap_distance"] = row["ap_distance_lo"] = row["ap_distance_hi"] = nan
    row["interval_note"] = interval_note(ci, r.objects.replicates)
    return row


def interval_note(ci: dict, replicates: int) -> str:
    """What a summary row's intervals need said: no bootstrap, too few resampling units
    (once), metrics without an interval and why, and replicates where metrics were
    undefined (grouped by count)."""
    if not replicates:
        return "no intervals (bootstrap off)"
    notes: list[str] = []
    undefined: dict[int, list[str]] = {}
    for k, iv in ci.items():
        if iv.method == "none" and iv.note:
            notes.append(f"{k}: {iv.note}")
        elif iv.note and iv.note not in notes:
            notes.insert(0, iv.note)
        if iv.undefined:
            undefined.setdefault(iv.undefined, []).append(k)
    for count, names in sorted(undefined.items(), reverse=True):
        notes.append(f"{count}/{replicates} replicates undefined: {', '.join(names)}")
    return "; ".join(notes)


def _timing_rows(ds: str, r: DetectorResult) -> list[list]:
    """Saved predictions have no detection time (their ``ms_per_image`` is empty: the time of
    reading a file is not a detector's speed); their images per second are the scoring's."""
    nan = float("nan")
    saved = r.saved_predictions
    ms = 1e3 * r.seconds / r.images if r.images and not saved else nan
    obj = 1e3 * r.object_seconds / r.images if r.images else nan
    total = obj if saved else ms + obj
    return [[ds, r.detector.name, r.images, ms, obj, 1e3 / total if r.images else nan]]


def timing_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """Detector and object-stage time per image, and images per second for both (timing
    is kept out of ``summary.csv`` so that the summary is identical across runs)."""
    return _frame(results, _timing_rows, TIMING_COLUMNS)


def _frame(results: dict[str, list[DetectorResult]], rows_of, columns: list[str]) -> pd.DataFrame:
    rows = [row for ds, rs in results.items() for r in rs for row in rows_of(ds, r)]
    return pd.DataFrame(rows, columns=columns)


def summary_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """Summary over datasets (``{dataset: results}``), columns :data:`SUMMARY_COLUMNS`."""
    return _frame(results, lambda ds, r: [summary_row(ds, r)], SUMMARY_COLUMNS)


def froc_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """The dense FROC under the matching rule: one row per detection score where the
    counted detections change (highest first; each row counts the detections scoring at or
    above its threshold), monotone in the threshold by construction. The threshold is on
    the detector's own score scale: the detections scoring at or above it."""
    parts = []
    for ds, rs in results.items():
        for r in rs:
            f = r.objects.froc()
            t, n = f["tp"].astype(np.int64), f["fp"].astype(np.int64)
            with np.errstate(invalid="ignore", divide="ignore"):
                precision = np.where(t + n > 0, t / np.maximum(t + n, 1), np.nan)
            parts.append(
                pd.DataFrame(
                    {
                        "dataset": ds,
                        "detector": r.detector.name,
                        "threshold": f["threshold"].astype(np.float64),
                        "tp": t,
                        "fp": n,
                        "false_alarms_per_image": f["fa_per_image"].astype(np.float64),
                        "pd_object": f["pd"].astype(np.float64),
                        "precision": precision,
                    },
                    columns=FROC_COLUMNS,
                )
            )
    parts = [p for p in parts if len(p)]
    if not parts:
        return pd.DataFrame(columns=FROC_COLUMNS)
    return pd.concat(parts, ignore_index=True)


def _pr_rows(ds: str, r: DetectorResult) -> list[list]:
    """COCO's interpolated precision at the 101 recall points reached (the exact curve
    behind AP50), with the score of the detection where each is reached: class ``all``
    class-agnostic; per class, then ``mean`` (their mean precision: the curve behind the
    mean AP50; no score)."""
    return [
        [ds, r.detector.name, cls, float(t), float(rc), float(p)]
        for cls, recall, precision, score in r.objects.pr_curves()
        for t, rc, p in zip(score, recall, precision, strict=True)
    ]


def pooled_pr(df: pd.DataFrame) -> pd.DataFrame:
    """The curve behind each AP50 of ``pr.csv``: class ``all`` (class-agnostic) or ``mean``
    (the mean over classes); every row of a table without classes."""
    if "class" not in df.columns:
        return df
    return df[df["class"].isin(["all", "mean"])]


def pr_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """Precision-recall points at IoU 0.5 (the curve behind AP50)."""
    return _frame(results, _pr_rows, PR_COLUMNS)


def _breakdown_rows(ds: str, r: DetectorResult) -> list[list]:
    """Per key; ground-truth classes carry false alarms (and so precision) only when the
    images have a class of their own, to which the false alarms are attributed."""
    rows = []
    keys = r.objects.breakdown(r.threshold)
    has_image_class = any(k.startswith("image_class:") for k in keys)
    nan = float("nan")
    class_ap = r.objects.class_ap()
    for key in sorted(keys):
        by, _, name = key.partition(":")
        k = keys[key]
        op = ratios(k["tp"], k["fp"], k["n_gt"], k["images"])
        if by == "class" and not has_image_class:
            if k["n_gt"] == 0:
                continue  # the sink of unattributed false alarms
            op.update(fp=nan, precision=nan, f1=nan)
        ap = class_ap.get(name, (nan, nan)) if by == "class" else (nan, nan)
        rows.append(
            [
                ds,
                r.detector.name,
                by,
                name,
                k["images"] or None,
                k["n_gt"],
                op["tp"],
                op["fp"],
                op["fn"],
                op["precision"],
                op["recall"],
                op["f1"],
                *ap,
            ]
        )
    return rows


def _scr_breakdown_rows(ds: str, r: DetectorResult) -> list[list]:
    """Per SCR bin (``by`` ``scr``: measured, ``scr_known``: declared by the data): targets,
    found and missed; false alarms have no SCR, so precision and F1 are NaN."""
    nan = float("nan")
    return [
        [
            ds,
            r.detector.name,
            "scr" if row["source"] == "measured" else f"scr_{row['source']}",
            row["scr_bin"],
            None,
            row["targets"],
            row["detected"],
            nan,
            row["targets"] - row["detected"],
            nan,
            row["pd"],
            nan,
            nan,
            nan,
        ]
        for row in r.objects.scr_rows(r.threshold)
    ]


def breakdown_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """Operating-point counts per ground-truth class, size bin, image class, group and
    signal-to-clutter ratio bin (measured, and known where the data declare it)."""
    return _frame(
        results,
        lambda ds, r: _breakdown_rows(ds, r) + _scr_breakdown_rows(ds, r),
        BREAKDOWN_COLUMNS,
    )


def _scr_rows(ds: str, r: DetectorResult) -> list[list]:
    return [[ds, r.detector.name, *row.values()] for row in r.objects.scr_rows(r.threshold)]


def scr_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """Pd versus signal-to-clutter ratio at the operating point: per SCR source
    (``measured`` on the image; ``known``: declared by the data, e.g. the simulator's) and
    bin, the targets, those detected, Pd with its 95 % Wilson score interval (targets
    counted as independent trials) and the bin's mean SCR; see
    :mod:`torchsar.metrics.scr` for the measurement and the bins."""
    return _frame(results, _scr_rows, SCR_COLUMNS)


def _errors_rows(ds: str, r: DetectorResult) -> list[list]:
    """False alarms per type, misses per size bin and per SCR bin, at the operating
    point (each family sums to the false alarms, resp. the missed targets)."""
    det, thr = r.detector.name, r.threshold
    counts = r.objects.fa_types(thr)
    rows = [[ds, det, "false_alarm", t, int(n)] for t, n in zip(FA_TYPES, counts, strict=True)]
    keys = r.objects.breakdown(thr)
    for name in r.objects.size_names:
        k = keys.get(f"size:{name}")
        rows.append([ds, det, "miss", f"size:{name}", 0 if k is None else k["n_gt"] - k["tp"]])
    for row in r.objects.scr_rows(thr):
        prefix = "scr" if row["source"] == "measured" else f"scr_{row['source']}"
        rows.append(
            [ds, det, "miss", f"{prefix}:{row['scr_bin']}", row["targets"] - row["detected"]]
        )
    return rows


def errors_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """SAR error types at the operating point: each false alarm counted under exactly one
    type (:data:`~torchsar.metrics.error_types.FA_TYPES`, see
    :mod:`torchsar.metrics.error_types`), and the missed targets by size bin and by SCR bin
    (bins without targets are left out)."""
    return _frame(results, _errors_rows, ERRORS_COLUMNS)


def _reference(metrics: list[dict]) -> int | None:
    """The position of the best F1 (the first of equals; ``None``: no F1 at all)."""
    best, ref = -1.0, None
    for k, m in enumerate(metrics):
        if m["f1"] == m["f1"] and m["f1"] > best:
            best, ref = m["f1"], k
    return ref


def paired_table(results: dict[str, list[DetectorResult]], level: float = 0.95) -> pd.DataFrame:
    """Each detector against the dataset's best (by F1): the difference ``detector -
    reference`` of F1 and recall at each one's operating point, Pd at 1 false alarm per
    image and AP50, with its paired interval (:mod:`torchsar.metrics.paired`: the two
    detectors' own intervals and their correlation over the paired bootstrap, whose
    replicate ``r`` resamples the same images or groups for every detector);
    ``significant`` when the interval excludes 0 (NaN intervals without replicates)."""
    rows = []
    for ds, rs in results.items():
        states = [side(r.objects, r.threshold, level) for r in rs]
        ref = _reference([m for m, _, _ in states])
        for k, r in enumerate(rs):
            if ref is None or k == ref:
                continue
            diffs = difference_intervals(states[k], states[ref])
            distance = r.scoring.matching.kind == "distance"
            for metric in PAIRED_METRICS:
                d, lo, hi = diffs[metric]
                name = "ap_distance" if distance and metric == "ap50" else metric
                rows.append(
                    [
                        ds,
                        r.detector.name,
                        rs[ref].detector.name,
                        name,
                        d,
                        lo,
                        hi,
                        bool(lo > 0 or hi < 0),
                    ]
                )
    return pd.DataFrame(rows, columns=PAIRED_COLUMNS)


def _coco_rows(ds: str, r: DetectorResult) -> list[list]:
    if r.coco is None:
        return []
    return [[ds, r.detector.name, r.coco_iou_type or "", *r.coco.stats().tolist()]]


def coco_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """``pycocotools``' 12 ``COCOeval.stats`` per dataset and detector (COCO-compatible
    scoring only; empty otherwise)."""
    return _frame(results, _coco_rows, COCO_COLUMNS)


def per_image_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """One row per image and detector at the design operating point."""
    return _frame(
        results, lambda ds, r: [[ds, r.detector.name, *row] for row in r.rows], PER_IMAGE_COLUMNS
    )


def pixel_roc_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """The scale-free pixel-level ROC per dataset and detector (those with pixel masks): one
    row per key of the statistic present (see :class:`~torchsar.metrics.RocAccumulator`),
    exact for ``statistic > threshold``, after a first row at ``-inf``."""
    frames = []
    for ds, rs in results.items():
        for r in rs:
            if not r.pixel_level:
                continue
            df = pd.DataFrame(r.roc.pixel_curve())
            df.insert(0, "detector", r.detector.name)
            df.insert(0, "dataset", ds)
            frames.append(df)
    cols = ["dataset", "detector", "threshold", "pd_pixel", "pfa_pixel"]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=cols)


HEADLINE_SHOWN = [
    "dataset",
    "detector",
    "images",
    "targets",
    "tp",
    "fp",
    "fn",
    "fom",
    "false_alarms_per_image",
]


def headline_table(summary: pd.DataFrame) -> pd.DataFrame:
    """The compact table of ``summary.md``: counts, what each row's matching measured, then
    the headline metrics and false alarms per image with their intervals as
    ``value [lo, hi]``, and the intervals' note. AP columns no row has (``ap50`` under the
    distance rule, ``ap_distance`` under an IoU rule) are left out."""
    out = summary[HEADLINE_SHOWN].copy()
    out.insert(2, "matching", summary["matching"])
    for m in [*HEADLINE, "ap_distance", "false_alarms_per_image"]:
        if m.startswith("ap") and summary[m].isna().all():
            continue
        out[m] = [
            _with_interval(v, lo, hi)
            for v, lo, hi in zip(summary[m], summary[f"{m}_lo"], summary[f"{m}_hi"], strict=True)
        ]
    if summary["ap50_95"].notna().any():
        out["ap50_95"] = summary["ap50_95"]
    out["interval_note"] = summary["interval_note"]
    return out


def _with_interval(v: float, lo: float, hi: float) -> str:
    """``value [lo, hi]``, or the value alone without an interval."""
    if lo != lo or hi != hi:
        return f"{v:.3g}"
    return f"{v:.3g} [{lo:.3g}, {hi:.3g}]"


def markdown(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    """A Markdown table (no optional dependency: formatted by hand)."""

    def fmt(v: object) -> str:
        return format(v, floatfmt) if isinstance(v, float) else str(v)

    head = "| " + " | ".join(df.columns) + " |"
    sep = "|" + "|".join("---" for _ in df.columns) + "|"
    body = ["| " + " | ".join(fmt(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join([head, sep, *body]) + "\n"
