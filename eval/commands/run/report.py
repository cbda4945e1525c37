"""What ``torchsar-eval run`` writes and prints: the tables, ``summary.md``, the plots and the
console summary."""

from __future__ import annotations

import csv
from pathlib import Path

import pandas as pd

from torchsar_eval.glossary import glossary
from torchsar_eval.plots import plot_roc
from torchsar_eval.runner import Scoring
from torchsar_eval.shards import shard_rows
from torchsar_eval.tables import (
    PER_IMAGE_COLUMNS,
    breakdown_table,
    froc_table,
    headline_table,
    markdown,
    pixel_roc_table,
    pr_table,
    summary_table,
    timing_table,
)

__all__ = ["SUMMARY_SHOWN", "print_summary", "write_tables"]

SUMMARY_SHOWN = [
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


def write_per_image(path: Path, folders: dict[str, Path]) -> None:
    """``per_image.csv`` streamed from the saved shards (memory independent of the dataset
    size): one row per image and detector, datasets and shards in order."""
    with open(path, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(PER_IMAGE_COLUMNS)
        for name, folder in folders.items():
            for det, rows in shard_rows(folder):
                out.writerows([name, det, *row] for row in rows)


def write_tables(
    tmp: Path, results: dict, scoring: Scoring, stats: dict, labels: dict[str, str]
) -> list[str]:
    """Every table and plot of a run into ``tmp``; returns the file names."""
    summary = summary_table(results)
    tables = {
        "summary.csv": summary,
        "roc.csv": froc_table(results),
        "pr.csv": pr_table(results),
        "roc_pixel.csv": pixel_roc_table(results),
        "breakdown.csv": breakdown_table(results),
        "timing.csv": timing_table(results),
    }
    for fname, df in tables.items():
        df.to_csv(tmp / fname, index=False)
    write_per_image(
        tmp / "per_image.csv", {n: tmp / "shards" / labels[n] / "test" for n in results}
    )
    text = glossary(summary, scoring) + "\n" + markdown(headline_table(summary))
    text += "\nEvery column, for every detector, is in `summary.csv`.\n"
    text += "\n## Timing\n\n" + markdown(tables["timing.csv"])
    text += "".join(
        f"\n- {name}: {st['images']} images in {st['wall_s']:.1f} s "
        f"({st['images_per_s']:.3g} images/s); shards {st['shards']}: done {st['done']}, "
        f"resumed {st['skipped']}, retried {st['retried']}, failed {len(st['failed'])}"
        + "".join(f"\n  - FAILED shard {f['shard']}: {f['error']}" for f in st["failed"])
        + (
            f"\n  - skipped {len(st['skipped_items'])} unreadable file(s)"
            if st["skipped_items"]
            else ""
        )
        + "".join(f"\n    - {b['file']}: {b['error']}" for b in st["skipped_items"])
        for name, st in stats.items()
    )
    (tmp / "summary.md").write_text(text)
    files = [*tables, "per_image.csv", "summary.md"]
    for name in results:
        sel = {k: df[df.dataset == name] for k, df in tables.items()}
        files += plot_roc(
            sel["roc_pixel.csv"], sel["roc.csv"], sel["pr.csv"], sel["summary.csv"],
            tmp / f"roc_{labels[name]}.png", name,
        )  # fmt: skip
    return files


def print_summary(out: Path, stats: dict, files: list[str]) -> None:
    """The console summary: the headline columns, each dataset's throughput and problems."""
    summary = pd.read_csv(out / "summary.csv").merge(
        pd.read_csv(out / "timing.csv"), on=["dataset", "detector", "images"]
    )
    print(summary[SUMMARY_SHOWN].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    for name, st in stats.items():
        print(
            f"{name}: {st['images']} images in {st['wall_s']:.1f} s "
            f"({st['images_per_s']:.3g} images/s), shards {st['shards']} "
            f"(done {st['done']}, resumed {st['skipped']}, retried {st['retried']}, "
            f"failed {len(st['failed'])})"
        )
        for f in st["failed"]:
            print(f"  FAILED shard {f['shard']}: {f['error']}")
        for b in st["skipped_items"]:
            print(f"  skipped unreadable {b['file']}")
    print(f"\nwrote {out}/: " + " ".join([*files, "config.json"]))
