"""Result tables (pandas): the run summary and the ROC points."""

from __future__ import annotations

import pandas as pd

from eval.runner import DetectorResult

__all__ = ["ROC_COLUMNS", "SUMMARY_COLUMNS", "pixel_roc_table", "roc_table", "summary_table"]

SUMMARY_COLUMNS = [
    "dataset",
    "detector",
    "images",
    "pd_pixel",
    "pfa_pixel",
    "pd_object",
    "false_alarms",
    "false_alarms_per_image",
    "fragmentation",
    "fom",
    "mean_iou",
    "ms_per_image",
]
ROC_COLUMNS = [
    "dataset",
    "detector",
    "threshold",
    "pd_pixel",
    "pfa_pixel",
    "pd_object",
    "false_alarms_per_image",
]


def summary_row(dataset: str, r: DetectorResult) -> dict:
    """One summary row at the detector's design operating point."""
    o = r.objects
    return {
        "dataset": dataset,
        "detector": r.spec.name,
        "images": r.images,
        "pd_pixel": r.pixels.pd,
        "pfa_pixel": r.pixels.pfa,
        "pd_object": o.pd,
        "false_alarms": o.false_alarms,
        "false_alarms_per_image": o.false_alarms_per_image,
        "fragmentation": o.fragmentation,
        "fom": o.fom,
        "mean_iou": o.mean_iou,
        "ms_per_image": 1e3 * r.seconds / r.images if r.images else float("nan"),
    }


def summary_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """Summary over datasets (``{dataset: results}``), columns :data:`SUMMARY_COLUMNS`."""
    rows = [summary_row(ds, r) for ds, rs in results.items() for r in rs]
    return pd.DataFrame(rows, columns=SUMMARY_COLUMNS)


def roc_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """Pixel and object ROC at the object-level thresholds, columns :data:`ROC_COLUMNS`."""
    frames = []
    for ds, rs in results.items():
        for r in rs:
            if r.roc is None:
                continue
            df = pd.DataFrame(r.roc.object_curve())
            df.insert(0, "detector", r.spec.name)
            df.insert(0, "dataset", ds)
            frames.append(df)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=ROC_COLUMNS)


def pixel_roc_table(results: dict[str, list[DetectorResult]]) -> pd.DataFrame:
    """The fine pixel-level ROC (every grid threshold) per dataset and detector."""
    frames = []
    for ds, rs in results.items():
        for r in rs:
            if r.roc is not None:
                df = pd.DataFrame(r.roc.pixel_curve())
                df.insert(0, "detector", r.spec.name)
                df.insert(0, "dataset", ds)
                frames.append(df)
    cols = ["dataset", "detector", "threshold", "pd_pixel", "pfa_pixel"]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=cols)


def markdown(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    """A Markdown table (no optional dependency: formatted by hand)."""

    def fmt(v: object) -> str:
        return format(v, floatfmt) if isinstance(v, float) else str(v)

    head = "| " + " | ".join(df.columns) + " |"
    sep = "|" + "|".join("---" for _ in df.columns) + "|"
    body = ["| " + " | ".join(fmt(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join([head, sep, *body]) + "\n"
