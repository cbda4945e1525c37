"""``torchsar-eval report``: rebuild a run folder's ``report.html`` from its files, or compare
several runs in one page.

The page is built from the run folder alone (its CSV tables, ``config.json``, figures and
``gallery/``), so any run folder can be reported again, older ones included: what a run lacks
is left out of the page.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from torchsar_eval.choices import RANK_METRICS, REPORT_FILE
from torchsar_eval.errors import EvalError

__all__ = ["WRITES_OUT", "add_parser", "run"]

WRITES_OUT = False
"""This command writes one HTML file, not a run folder (no ``--overwrite``)."""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "report",
        help="rebuild a run's report.html, or compare several runs in one page",
        description="Build the self-contained HTML report (leaderboards, curves, worst cases) "
        "of a run folder from its files; with several run folders, one page comparing them.",
    )
    p.add_argument(
        "runs",
        nargs="+",
        type=Path,
        metavar="RUN",
        help="run folder(s) of torchsar-eval run",
    )
    p.add_argument(
        "--out",
        dest="file",
        type=Path,
        default=None,
        metavar="FILE",
        help=f"the HTML file to write (default: RUN/{REPORT_FILE} for one run; needed when "
        "comparing several)",
    )
    p.add_argument(
        "--rank-by",
        default=None,
        metavar="METRIC",
        help="metric that ranks the leaderboards: "
        f"{', '.join(RANK_METRICS)} (default: the run's own, else f1)",
    )
    p.set_defaults(func=run, claims_out=True)


def run(args: argparse.Namespace) -> int:
    """The ``report`` sub-command: build and write the page, print where it is."""
    from torchsar_eval.html_report import write_report

    if args.file is None and len(args.runs) > 1:
        raise EvalError(f"comparing {len(args.runs)} runs: name the page with --out FILE.html")
    if args.file is not None:
        if args.file.suffix.lower() not in (".html", ".htm"):
            raise EvalError(f"--out {args.file}: the report is an HTML file; name it *.html")
        if args.file.is_dir():
            raise EvalError(f"--out {args.file} is a folder; name the HTML file to write")
        if not args.file.parent.is_dir():
            raise EvalError(f"--out {args.file}: folder {args.file.parent} does not exist")
    try:
        path = write_report(args.runs, args.file, rank_by=args.rank_by)
    except OSError as exc:
        raise EvalError(f"cannot write the report ({exc.strerror or exc})") from exc
    print(f"wrote {path}")
    return 0
