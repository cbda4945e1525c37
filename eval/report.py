"""The tables of a run and what a run folder holds: the CSV tables, ``summary.md`` and the
plots."""

from __future__ import annotations

import csv
import json
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import IO

import pandas as pd

from torchsar_eval.gallery import write_gallery
from torchsar_eval.glossary import glossary
from torchsar_eval.html_report import DEFAULT_RANK, REPORT_FILE, write_report
from torchsar_eval.html_report.runfiles import RUN_TABLES, read_run
from torchsar_eval.latex import summary_tex
from torchsar_eval.leaderboard import LOWER_IS_BETTER, Board, caveats
from torchsar_eval.overlays import write_overlays
from torchsar_eval.panels import plot_roc
from torchsar_eval.result import Scoring
from torchsar_eval.tables import (
    PER_IMAGE_COLUMNS,
    headline_table,
    markdown,
)

__all__ = [
    "TABLE_FILES",
    "per_image_rows",
    "ranked_summary",
    "throughput",
    "write_run",
]

SUMMARY_TEX = "summary.tex"
"""The run's headline tables in LaTeX (:func:`~torchsar_eval.latex.summary_tex`)."""
TABLE_FILES = {k: f for k, f in RUN_TABLES.items() if k not in ("cases", "sweep", "overlays")}
"""Each table of :func:`~torchsar_eval.results.result_tables` and its file in a run folder."""


def per_image_rows(folders: dict[str, Iterable[tuple[str, list]]]) -> Iterator[list]:
    """``per_image.csv`` rows from each dataset's ``(detector, rows)`` stream (the saved
    shards, in order), sorted by dataset, then detector (the run's order), then image (the
    dataset's order): the same file for any shard size, worker count or resume.

    Each detector's rows are spooled to a temporary file while the shards are read once, so
    memory does not grow with the dataset.

    Examples:
        >>> shards = [("ca", [("a", 1)]), ("so", [("a", 2)]), ("ca", [("b", 3)]),
        ...           ("so", [("b", 4)])]
        >>> list(per_image_rows({"d": shards}))
        [['d', 'ca', 'a', 1], ['d', 'ca', 'b', 3], ['d', 'so', 'a', 2], ['d', 'so', 'b', 4]]
    """
    for name, parts in folders.items():
        with ExitStack() as stack:
            spools: dict[str, IO[str]] = {}
            for det, rows in parts:
                if det not in spools:
                    spools[det] = stack.enter_context(tempfile.TemporaryFile("w+"))
                spools[det].write(json.dumps(list(rows)) + "\n")  # data only: JSON lines
            for det, spool in spools.items():
                spool.seek(0)
                for line in spool:
                    for row in json.loads(line):
                        yield [name, det, *row]


def throughput(st: dict) -> str:
    """How a dataset's images were scored: those scored in this run apart from those reused
    from an interrupted run's saved shards (``--resume``), and the shards.

    Examples:
        >>> st = {"images": 3000, "scored": 1000, "reused": 2000, "wall_s": 28.3,
        ...       "images_per_s": 35.3, "shards": 12, "done": 4, "skipped": 8, "retried": 0,
        ...       "failed": []}
        >>> for part in throughput(st).split("; "):
        ...     print(part)
        1000 scored in 28.3 s (35.3 images/s), 2000 reused from the saved run
        shards 12: done 4, resumed 8, retried 0, failed 0
    """
    scored, reused = st.get("scored", st["images"]), st.get("reused", 0)
    if scored:
        text = (
            f"{scored} {'scored' if reused else 'images'} in {st['wall_s']:.1f} s "
            f"({st['images_per_s']:.3g} images/s)"
        )
    else:
        text = f"nothing scored ({st['wall_s']:.1f} s)"
    if reused:
        text += f", {reused} reused from the saved run"
    return (
        f"{text}; shards {st['shards']}: done {st['done']}, resumed {st['skipped']}, "
        f"retried {st['retried']}, failed {len(st['failed'])}"
    )


def _stats_lines(stats: dict) -> str:
    return "".join(
        f"\n- {name}: {throughput(st)}"
        + "".join(f"\n  - FAILED shard {f['shard']}: {f['error']}" for f in st["failed"])
        + (
            f"\n  - skipped {len(st['skipped_items'])} unreadable file(s)"
            if st["skipped_items"]
            else ""
        )
        + "".join(f"\n    - {b['file']}: {b['error']}" for b in st["skipped_items"])
        for name, st in stats.items()
    )


def ranked_summary(folder: Path, summary: pd.DataFrame, rank_by: str) -> str:
    """``summary.md``'s tables: per dataset, its detectors best first by ``rank_by`` (the
    same ranking, notes and caveats as ``report.html``), from the tables already written
    to ``folder``."""
    run = read_run(folder)
    head = headline_table(summary)
    arrow = "lower is better" if rank_by in LOWER_IS_BETTER else "higher is better"
    parts = []
    for dataset in run.datasets:
        board = Board([run], dataset, rank_by)
        rows = head[head["dataset"].astype(str) == dataset].drop(columns="dataset")
        rows = rows.set_index(rows["detector"].astype(str)).loc[board.rows["detector"]]
        rows.insert(0, "rank", ["–" if r is None else r for r in board.rank])
        if rank_by in board.rows.columns and rank_by not in rows.columns:
            rows.insert(2, rank_by, board.rows[rank_by].to_numpy())
        rows["note"] = board.notes
        parts.append(
            f"\n## {dataset}: ranked by {rank_by} ({arrow})\n\n"
            + markdown(rows.reset_index(drop=True))
        )
        notes = caveats(run, dataset, board)
        parts += ["\n"] + [f"- {c}\n" for c in notes] if notes else []
    return "".join(parts)


def write_run(
    tmp: Path,
    tables: dict[str, pd.DataFrame],
    per_image: Iterable[list],
    scoring: Scoring,
    stats: dict,
    labels: dict[str, str],
    *,
    results: dict | None = None,
    rank_by: str = DEFAULT_RANK,
    overlays: dict | None = None,
    figures: bool = True,
) -> list[str]:
    """Every table and plot of a run into ``tmp``; returns the file names. ``per_image``
    is streamed to ``per_image.csv`` (memory independent of the dataset size). With the
    merged ``results`` (``{dataset: [DetectorResult]}``), each detector's worst cases go to
    ``gallery/``; the ``overlays`` (``{dataset: [Overlay]}``) to ``overlays/``; last,
    ``report.html`` is built from the folder's files (and its
    ``config.json``, when written first), its leaderboards ranked by ``rank_by``. Without
    ``figures``, no curve, gallery or page (overlays asked for are still drawn)."""
    written = [f for k, f in TABLE_FILES.items() if k != "coco" or not tables[k].empty]
    for key, fname in TABLE_FILES.items():
        if fname in written:
            tables[key].to_csv(tmp / fname, index=False)
    with open(tmp / "per_image.csv", "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(PER_IMAGE_COLUMNS)
        out.writerows(per_image)
    summary = tables["summary"]
    text = glossary(summary, scoring) + ranked_summary(tmp, summary, rank_by)
    text += "\nEvery column, for every detector, is in `summary.csv`.\n"
    if not tables["coco"].empty:
        text += (
            "\n## COCO-compatible (pycocotools' 12 stats: per category, 100 detections "
            "per image and category, COCO area ranges)\n\n" + markdown(tables["coco"])
        )
    text += "\n## Timing\n\n" + markdown(tables["timing"]) + _stats_lines(stats)
    (tmp / "summary.md").write_text(text)
    run = read_run(tmp)
    order = {
        d: Board([run], d, rank_by).rows["detector"].astype(str).tolist() for d in run.datasets
    }
    (tmp / SUMMARY_TEX).write_text(summary_tex(summary, order))
    files = [*written, "per_image.csv", "summary.md", SUMMARY_TEX]
    if overlays:
        files += write_overlays(tmp, overlays, labels)
    if not figures:
        return files
    for name, label in labels.items():
        sel = {k: df[df.dataset == name] for k, df in tables.items()}
        files += plot_roc(
            sel["pixel_roc"],
            sel["froc"],
            sel["pr"],
            sel["summary"],
            tmp / f"roc_{label}.png",
            name,
        )
    if results is not None:
        files += write_gallery(tmp, results, labels)
    write_report(tmp, tmp / REPORT_FILE, rank_by=rank_by)
    return [*files, REPORT_FILE]
