"""The glossary that opens ``summary.md``: what each column means, under which rule."""

from __future__ import annotations

import pandas as pd

from torchsar.metrics.scr import SCR_GUARD, SCR_WIDTH

__all__ = ["MATCHING_RULES", "TERMS", "glossary"]

MATCHING_RULES = {
    "centroid": "prescreening rule: a detection hits a target when its centroid lies in the "
    "target box grown by {margin:g} x its larger side and its box is at most "
    "{max_size_ratio:g}x the target box",
    "mask": "mask IoU >= {iou:g}",
    "box": "box IoU >= {iou:g}",
    "distance": "distance rule: a detection's point or centroid and a target's centroid closer "
    "than {max_distance:g} {distance_units}, assigned {assign} at the operating point",
}

TERMS = [
    ("images, targets", "images scored; ground-truth instances (ignore regions excluded)"),
    (
        "pd_pixel, pfa_pixel",
        "detected target pixels / target pixels; detected clutter pixels / "
        "clutter pixels (ignore pixels excluded)",
    ),
    (
        "tp, fp, fn",
        "objects matched one-to-one to targets (each target at most once, "
        "detections in descending score order); unmatched objects; missed targets",
    ),
    ("precision, recall (= pd_object), f1", "tp/(tp+fp), tp/targets, 2tp/(2tp+fp+fn)"),
    ("fom", "figure of merit tp/(fp+targets)"),
    (
        "false_alarms_per_image, fa_per_km2",
        "fp per image; fp per km² of scored image area (only when every image has a pixel spacing)",
    ),
    (
        "ap50, ap50_95",
        "COCO average precision (101-point) at IoU 0.5, and averaged over IoU "
        "0.50:0.05:0.95; exact (pycocotools' ranking, no per-image detection cap). The IoU "
        "of each row is in iou_type: mask IoU where the detector gives masks and the "
        "targets are masks; box IoU under --match box, for box detectors and box "
        "predictions (against each mask target's bounding box) and on box targets; "
        "mask+box where only some targets are masks",
    ),
    (
        "iou_type, matching",
        "what a row's AP measured (mask, box, mask+box, point, "
        "distance) and its operating point's matching rule in words",
    ),
    (
        "ap_distance",
        "under --match distance: AP with pairs closer than the tolerance (no "
        "IoU: ap50 and ap50_95 are empty)",
    ),
    (
        "ap_small, ap_medium, ap_large",
        "ap50_95 in COCO's area ranges (targets outside the range ignored, as pycocotools)",
    ),
    (
        "classes",
        "per-class: detections matched within their class, AP the mean over the "
        "classes with targets (COCO); agnostic: every class pooled",
    ),
    (
        "pd_at_F_fa_per_image",
        "FROC read at F false alarms per image as a step function (no "
        "interpolation): the recall of the lowest score level with at most F false alarms per "
        "image, objects ranked by score",
    ),
    (
        "pauc",
        "mean recall over 0-1 false alarms per image (area under that step function, normalised)",
    ),
    (
        "X_lo, X_hi",
        "95 % interval over images, from a Poisson bootstrap that resamples whole "
        "images (the targets of one image stay together): for precision, recall, f1, fom, "
        "ap50, pd_at_F_fa_per_image and pauc, Jeffreys' interval on the effective count (the "
        "count divided by the design effect the bootstrap's variance shows, times Korn & "
        "Graubard's (t_{n-1}/t_{images-1})², n the count, for few images; Clopper-Pearson's "
        "bound at 0 and at 1, so never zero width), f1, ap50, pd_at_F and pauc centred on the "
        "bootstrap's bias-corrected point (an interval always holds its point); for "
        "false_alarms_per_image, Jeffreys' Poisson "
        "interval on the effective number of images (Garwood's exact upper bound at zero false "
        "alarms; fa_per_km2: the same per km²). No interval: ap50_95 (not resampled), pixel "
        "pd/pfa, mean_iou, fragmentation, length_score (descriptive). Coverage measured on "
        "simulated data: README",
    ),
    (
        "interval_note",
        "what to know about a row's intervals: fewer than 10 resampling "
        "units (the level rests on the Student factor), a metric without an interval and why, "
        "bootstrap replicates where a metric was undefined (left out of the variance)",
    ),
    (
        "mean_iou, fragmentation",
        "mean IoU of the matched pairs; objects touching each found target",
    ),
    (
        "score_threshold",
        "the operating threshold on the detector's own score scale (a "
        "statistic's design threshold, a declared or a calibrated one): objects scoring above "
        "it count at the operating point; -inf: every object counts",
    ),
    (
        "ms_per_image, object_ms_per_image",
        "detector time (incl. despeckling); object stage + matching time",
    ),
]


_FILES = [
    (
        "scr.csv",
        "Pd per signal-to-clutter ratio bin at the operating point. SCR = 10 log10("
        "target mean intensity / clutter mean) on the image before any speckle filter; the "
        f"clutter is a ring {SCR_WIDTH} px wide starting {SCR_GUARD + 1} px outside the target's "
        "bounding box (Chebyshev distance), other targets, ignore pixels and no-data left out. "
        "`source` measured, or "
        "known where the data declare it (the simulator's target level over its clutter mean). "
        "Bins [lo, hi) dB: <0, 0-5, 5-10, 10-15, 15-20, >=20, n/a (no clutter in the ring); "
        "pd_lo, pd_hi: 95 % Wilson interval, targets counted as independent trials. The same "
        "bins are in `breakdown.csv` (by scr, scr_known)",
    ),
    (
        "errors.csv",
        "SAR error types at the operating point. Each false alarm (an unmatched "
        "detection) gets the first that applies: **merge** touches two or more targets; "
        "**duplicate** touches one target already matched by a higher-scored detection and "
        "covers at least half of it; **fragment** the same but covering less than half; "
        "**localisation** touches one target not matched by a higher-scored detection (it "
        "overlaps but fails the matching rule); **shadow** touches no target but lies on a "
        "target's radar shadow (simulated data, and folder / Phoenix data with shadow=ignore; "
        "0 elsewhere: no shadow mask); **clutter** everything else. Touching: sharing a pixel "
        "(boxes: intersecting; distance rule: within the tolerance). Misses by size bin and "
        "SCR bin",
    ),
    (
        "paired.csv",
        "each detector minus the dataset's best by F1 (`reference`) in F1, recall, "
        "Pd at 1 false alarm per image and AP50, with a 95 % interval: the two detectors' own "
        "intervals (as in the summary) combined by square-and-add with the correlation of "
        "their paired bootstrap replicates (every detector's replicates resample the same "
        "images, or groups with --bootstrap-unit group); exactly 0 where the two agree on the "
        "sample and on every replicate; `significant`: the interval excludes 0",
    ),
]


def glossary(summary: pd.DataFrame, scoring) -> str:
    """Markdown glossary for a run's summary (the matching rule and the N targets)."""
    m = scoring.matching
    rule = MATCHING_RULES[m.kind].format(**m.as_dict())
    r = scoring.rules
    cut = "the design threshold" if r.floor == 1 else f"{r.floor:g} x the design threshold"
    top = "∞" if r.max_area is None else f"{r.max_area:g}"
    stage = (
        f"closing radius {r.closing} px, {r.connectivity}-connected components over {cut}, "
        f"area {r.min_area:g}–{top} {r.units}"
    )
    lines = [
        "# Run summary",
        "",
        "Every detector goes through the same discrimination stage: " + stage + ". An "
        "object's score is the peak of the detector's own statistic over its pixels (its "
        "design threshold as the operating threshold, `score_threshold`; statistic / "
        "threshold where the threshold varies over a batch). Operating point = every "
        "object above its detector's threshold; "
        f"matching rule: {rule}.",
        "",
    ]
    for ds, df in summary.groupby("dataset", sort=False):
        lines.append(
            f"- {ds}: {int(df['images'].iloc[0])} images, {int(df['targets'].iloc[0])} targets"
        )
    lines += ["", "| column | meaning |", "|---|---|"]
    unit = getattr(scoring, "bootstrap_unit", "image")
    for k, v in TERMS:
        if unit == "group" and k == "X_lo, X_hi":
            v = v.replace("over images", "over groups of images (meta group)")
            v = v.replace(
                "resamples whole images (the targets of one image stay together)",
                "resamples whole groups (the images of one group stay together)",
            )
        lines.append(f"| {k} | {v} |")
    lines += ["", "| file | meaning |", "|---|---|"]
    lines += [f"| `{k}` | {v} |" for k, v in _FILES]
    return "\n".join(lines) + "\n"
