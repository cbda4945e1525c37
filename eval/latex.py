"""``summary.tex``: a run's headline metrics as LaTeX tables a paper can include as they are
(booktabs rules, intervals as ``x [lo, hi]``, the best value of each column in bold, what
each row measured).

One ``table`` per dataset, rows ranked as the leaderboard ranks them. Needs only
``\\usepackage{booktabs}`` in the preamble. Numbers are the ones of ``summary.csv``, rounded
for print (three decimals for rates, three significant digits for false alarms per image).
"""

from __future__ import annotations

import math

import pandas as pd

from torchsar_eval.leaderboard import LOWER_IS_BETTER

__all__ = ["COLUMNS", "escape", "summary_tex"]

COLUMNS = [
    ("precision", "Precision"),
    ("recall", "Recall"),
    ("f1", "F1"),
    ("ap50", "AP$_{50}$"),
    ("ap_distance", "AP$_\\mathrm{dist}$"),
    ("pd_at_1_fa_per_image", "Pd @ 1 FA/img"),
    ("false_alarms_per_image", "FA/img"),
]
"""The metric columns of a table (those with a value in some row), with their headers."""

_SPECIAL = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
    "<": r"\textless{}",
    ">": r"\textgreater{}",
}


def escape(text: object) -> str:
    r"""``text`` with LaTeX's special characters escaped.

    Examples:
        >>> escape("ca_2 & 50%")
        'ca\\_2 \\& 50\\%'
    """
    return "".join(_SPECIAL.get(c, c) for c in str(text))


def number(metric: str, v: float) -> str:
    """A value as printed: three decimals for a rate, three significant digits for false
    alarms per image; ``--`` for no value.

    Examples:
        >>> number("f1", 0.81234), number("false_alarms_per_image", 12.345), number("f1", math.nan)
        ('0.812', '12.3', '--')
    """
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "--"
    if metric == "false_alarms_per_image":
        return f"{v:.3g}"
    return f"{v:.3f}"


def _cell(metric: str, row: pd.Series, best: bool) -> str:
    value = number(metric, row[metric])
    if best:
        value = rf"\textbf{{{value}}}"
    lo, hi = row.get(f"{metric}_lo"), row.get(f"{metric}_hi")
    if (
        value != "--"
        and lo is not None
        and hi is not None
        and not (math.isnan(lo) or math.isnan(hi))
    ):
        value += rf" {{\footnotesize [{number(metric, lo)}, {number(metric, hi)}]}}"
    return value


def _best(values: pd.Series, metric: str) -> float:
    """The best printed value of a column (ties in print are all best)."""
    shown = pd.to_numeric(values, errors="coerce").dropna()
    if shown.empty:
        return math.nan
    rounded = shown.map(lambda v: float(number(metric, v)))
    return rounded.min() if metric in LOWER_IS_BETTER else rounded.max()


def dataset_table(dataset: str, rows: pd.DataFrame) -> str:
    """One dataset's ``table`` (``rows``: its summary rows, in the order to print)."""
    metrics = [(m, h) for m, h in COLUMNS if m in rows.columns and rows[m].notna().any()]
    best = {m: _best(rows[m], m) for m, _ in metrics}
    rules = rows["matching"].astype(str).unique() if "matching" in rows.columns else []
    shared = len(rules) == 1  # one rule for every row: said once, in the caption
    spec = ("l" if shared else "ll") + "r" * len(metrics)
    head = " & ".join(["Detector", *([] if shared else ["Measured by"]), *(h for _, h in metrics)])
    said = f"; matching: {escape(rules[0])}" if shared else ""
    lines = [
        r"\begin{table}[t]",
        r"\centering",
        rf"\caption{{{escape(dataset)}: {len(rows)} detectors, "
        rf"{int(rows['images'].iloc[0])} images, {int(rows['targets'].iloc[0])} targets{said}; "
        r"95\,\% intervals in brackets, best in bold.}",
        r"\small",
        rf"\begin{{tabular}}{{{spec}}}",
        r"\toprule",
        head + r" \\",
        r"\midrule",
    ]
    for _, row in rows.iterrows():
        cells = [escape(row["detector"]), *([] if shared else [escape(row["matching"])])]
        for m, _ in metrics:
            printed = number(m, row[m])
            cells.append(_cell(m, row, printed != "--" and float(printed) == best[m]))
        lines.append(" & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}", rf"\label{{tab:{_label(dataset)}}}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def _label(dataset: str) -> str:
    return "".join(c if c.isalnum() else "-" for c in dataset).strip("-") or "dataset"


def summary_tex(summary: pd.DataFrame, order: dict[str, list[str]] | None = None) -> str:
    """``summary.tex``: one table per dataset of ``summary`` (``summary.csv``'s rows), its
    detectors in ``order[dataset]`` (the leaderboard's ranking; default: as given).

    Examples:
        >>> s = pd.DataFrame({"dataset": ["d", "d"], "detector": ["ca", "so"],
        ...                   "images": [4, 4], "targets": [4, 4],
        ...                   "matching": ["box IoU >= 0.5"] * 2,
        ...                   "f1": [0.5, 0.8], "f1_lo": [0.2, 0.6], "f1_hi": [0.7, 0.9]})
        >>> [line for line in summary_tex(s).splitlines() if line.startswith("so")]
        ['so & \\\\textbf{0.800} {\\\\footnotesize [0.600, 0.900]} \\\\\\\\']
    """
    parts = [
        "% torchsar-eval summary: include with \\input{summary.tex}; needs \\usepackage{booktabs}\n"
    ]
    for dataset, rows in summary.groupby("dataset", sort=False):
        if order and dataset in order:
            rows = rows.set_index("detector", drop=False).loc[order[dataset]]
        parts.append(dataset_table(str(dataset), rows.reset_index(drop=True)))
    return "\n".join(parts)
