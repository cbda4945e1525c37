"""Coverage of the evaluator's 95 % intervals on many small seeded simulated datasets.

A pool of simulated images (``sim-chips`` or ``sim-scenes``, one seed) is scored once per
detector through the harness's own scoring (discrimination stage, matching, object state);
consecutive blocks of ``n`` images form the small datasets of each cell (``n`` in
``--sizes``), and the whole pool (every block together, ``datasets x max(sizes)`` images)
gives the truth. For each small dataset and headline metric the script records the point,
the natural count, the bootstrap replicates' mean / variance / undefined count, the
resampling units and the plain percentile endpoints, so any interval rule can be judged
afterwards without scoring again (``--report`` on the records file).

Resumable: records go to ``OUT/records.jsonl`` and the truth states to ``OUT/truth.state``
after every block of the largest size; a rerun with the same options continues.

Usage::

    python scripts/interval_coverage.py --kind sim-chips --sizes 36 200 --datasets 200 \
        --out cov-chips
    python scripts/interval_coverage.py --kind sim-scenes --sizes 4 36 --datasets 40 \
        --out cov-scenes
    python scripts/interval_coverage.py --report cov-chips cov-scenes
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

# this file's name shadows the ``coverage`` package (numba imports it): drop its folder
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]

import numpy as np  # noqa: E402
import torch  # noqa: E402

from torchsar.metrics import ObjectState  # noqa: E402
from torchsar.metrics.assign import match_batch  # noqa: E402
from torchsar.metrics.bootstrap import interval as percentile  # noqa: E402
from torchsar.metrics.intervals import (  # noqa: E402
    PROPORTIONS,
    ReplicateSpread,
    proportion_interval,
    rate_interval,
)
from torchsar_eval import shards, statefile  # noqa: E402, F401  (shards registers the states)
from torchsar_eval.batches import Indexed, batches  # noqa: E402
from torchsar_eval.datasets.sim import SimDataset  # noqa: E402
from torchsar_eval.registry import load  # noqa: E402
from torchsar_eval.result import DetectorResult, Scoring  # noqa: E402
from torchsar_eval.scoring import batch_truth  # noqa: E402

METRICS = ["precision", "recall", "f1", "ap50", "pd_at_1_fa_per_image", "fa_per_image"]


def _record(state: ObjectState) -> dict:
    """What one small dataset says about each metric (see the module docstring)."""
    m, reps = state.metrics(), state.replicate_metrics()
    out = {"units": state.units, "n_gt": state.n_gt, "tp": m["tp"], "fp": m["fp"]}
    for k in METRICS:
        v = np.asarray(reps[k], dtype=np.float64)
        ok = np.isfinite(v)
        lo, hi = percentile(v)
        out[k] = {
            "point": m[k],
            "mean": float(v[ok].mean()) if ok.any() else math.nan,
            "var": float(v[ok].var(ddof=1)) if ok.sum() > 1 else math.nan,
            "used": int(ok.sum()),
            "undefined": int((~ok).sum()),
            "pct": [lo, hi],
        }
    return out


def _truth(state: ObjectState) -> dict:
    m = state.metrics()
    return {k: m[k] for k in METRICS}


def score(args) -> None:
    """Score the pool and write the records (resuming where a previous run stopped)."""
    torch.set_num_threads(1)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sizes, big = sorted(args.sizes), max(args.sizes)
    step = math.gcd(*sizes)
    total = args.datasets * big
    done_path, rec_path, truth_path = (
        out / "progress.json",
        out / "records.jsonl",
        out / "truth.state",
    )
    settings = {
        k: getattr(args, k)
        for k in ("kind", "sizes", "datasets", "detectors", "replicates", "seed")
    }
    start = 0
    truth: dict[str, ObjectState] = {}
    if done_path.exists():
        saved = json.loads(done_path.read_text())
        if saved["settings"] != settings:
            raise SystemExit(f"{out} holds a run with other settings: {saved['settings']}")
        start = saved["images"]
        truth = statefile.loads(truth_path.read_bytes())
    else:
        rec_path.unlink(missing_ok=True)
    scoring = Scoring(replicates=args.replicates, seed=args.seed)
    dets = [load(d) for d in args.detectors]
    shells = {d.name: DetectorResult(d, scoring) for d in dets}
    truth = truth or {d.name: ObjectState(replicates=0) for d in dets}
    ds = SimDataset(args.kind, total, args.seed)
    open_states: dict[tuple[str, int], ObjectState] = {}
    t0 = time.perf_counter()
    for i in range(start, total, step):
        sub = Indexed(ds, range(i, i + step))
        batch = next(iter(batches(sub, step)))
        gt, info = batch_truth(batch, args.kind)
        for d in dets:
            obj = shells[d.name].objects_of(d(batch["image"], batch["meta"]), batch)
            m = match_batch(obj, gt, scoring.matching)
            truth[d.name].update(m, obj, gt, info)
            for n in sizes:
                st = open_states.setdefault((d.name, n), ObjectState(args.replicates, args.seed))
                st.update(m, obj, gt, info)
        end = i + step
        lines = []
        for (name, n), st in list(open_states.items()):
            if end % n == 0:
                lines.append({"detector": name, "size": n, "dataset": end // n - 1, **_record(st)})
                del open_states[(name, n)]
        if lines:
            with rec_path.open("a") as f:
                f.writelines(json.dumps(r) + "\n" for r in lines)
        if end % big == 0:
            truth_path.write_bytes(statefile.dumps(truth))
            done_path.write_text(json.dumps({"settings": settings, "images": end}))
            rate = (end - start) / (time.perf_counter() - t0)
            print(f"{end}/{total} images ({rate:.1f}/s)", flush=True)
    print(json.dumps({k: _truth(v) for k, v in truth.items()}))


def _interval(metric: str, r: dict, rule: str) -> tuple[float, float]:
    """The interval of one record under a rule: ``pct`` (plain percentile), or
    ``KIND[-bc][-nocap]`` with KIND ``cp`` (Clopper-Pearson / exact Poisson) or ``jeffreys``
    on the effective count, ``-bc`` bias-corrected, ``-nocap`` the effective count not capped
    at the real one; ``default``: the library's own choice."""
    x = r[metric]
    if rule == "pct":
        return tuple(x["pct"])
    s = ReplicateSpread(x["mean"], x["var"], x["used"], x["undefined"])
    if rule == "default":
        kind, bias, cap = None, PROPORTIONS.get(metric, False), None
    else:
        kind, bias, cap = rule.split("-")[0], "-bc" in rule, "-nocap" not in rule
    opts = (
        {}
        if kind is None
        else {"kind": kind if metric != "fa_per_image" or kind != "cp" else "exact", "cap": cap}
    )
    if metric == "fa_per_image":
        iv = rate_interval(r["fp"], r["units"], s, 0.95, **opts)
    else:
        counts = {
            "precision": r["tp"] + r["fp"],
            "f1": r["tp"] + (r["fp"] + r["n_gt"] - r["tp"]) / 2,
        }
        iv = proportion_interval(
            x["point"], counts.get(metric, r["n_gt"]), s, r["units"], 0.95, bias, **opts
        )
    return iv.lo, iv.hi


def report(folders: list[str], rules: list[str]) -> None:
    """Coverage per cell (kind, size, detector), metric and rule, with its Monte-Carlo
    standard error, mean width and zero-width count."""
    print("| data | n | detector | metric | truth | rule | coverage ± MC se | mean width | "
          "zero-width | datasets |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for folder in folders:
        out = Path(folder)
        settings = json.loads((out / "progress.json").read_text())["settings"]
        states = statefile.loads((out / "truth.state").read_bytes())  # up to the last block
        truth = {k: _truth(v) for k, v in states.items()}
        recs = [json.loads(line) for line in (out / "records.jsonl").read_text().splitlines()]
        cells: dict = {}
        for r in recs:
            cells.setdefault((r["size"], r["detector"]), []).append(r)
        for (n, det), rs in sorted(cells.items()):
            for metric in METRICS:
                t = truth[det][metric]
                for rule in rules:
                    ivs = np.array([_interval(metric, r, rule) for r in rs], dtype=np.float64)
                    ok = np.isfinite(ivs).all(axis=1)
                    cover = (ivs[ok, 0] <= t) & (t <= ivs[ok, 1])
                    c = cover.mean() if ok.any() else math.nan
                    se = math.sqrt(c * (1 - c) / ok.sum()) if ok.any() else math.nan
                    zero = int((ivs[ok, 1] - ivs[ok, 0] == 0).sum())
                    width = float((ivs[ok, 1] - ivs[ok, 0]).mean()) if ok.any() else math.nan
                    print(
                        f"| {settings['kind']} | {n} | {det} | {metric} | {t:.4g} | {rule} | "
                        f"{c:.3f} ± {se:.3f} | {width:.3g} | {zero} | {ok.sum()}/{len(rs)} |"
                    )


def compact(folders: list[str], rule: str = "default") -> None:
    """One row per cell: the coverage of each metric under ``rule`` (its Monte-Carlo
    standard error in the header: the largest of the row), and the zero-width intervals."""
    print(f"| data | images | detector | datasets | {' | '.join(METRICS)} | MC se | zero-width |")
    print("|---|---|---|---|" + "---|" * len(METRICS) + "---|---|")
    for folder in folders:
        out = Path(folder)
        kind = json.loads((out / "progress.json").read_text())["settings"]["kind"]
        states = statefile.loads((out / "truth.state").read_bytes())
        truth = {k: _truth(v) for k, v in states.items()}
        recs = [json.loads(line) for line in (out / "records.jsonl").read_text().splitlines()]
        cells: dict = {}
        for r in recs:
            cells.setdefault((r["size"], r["detector"]), []).append(r)
        for (n, det), rs in sorted(cells.items()):
            cols, ses, zero = [], [], 0
            for metric in METRICS:
                t = truth[det][metric]
                ivs = np.array([_interval(metric, r, rule) for r in rs], dtype=np.float64)
                ok = np.isfinite(ivs).all(axis=1)
                c = float(((ivs[ok, 0] <= t) & (t <= ivs[ok, 1])).mean())
                ses.append(math.sqrt(max(c * (1 - c), 0.05 * 0.95) / ok.sum()))
                zero += int((ivs[ok, 1] == ivs[ok, 0]).sum())
                cols.append(f"{c:.3f}" + ("" if ok.all() else f" ({ok.sum()} defined)"))
            print(
                f"| {kind} | {n} | {det} (truth P {truth[det]['precision']:.3f}, "
                f"AP50 {truth[det]['ap50']:.3f}) | {len(rs)} | {' | '.join(cols)} | "
                f"{max(ses):.3f} | {zero} |"
            )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--kind", choices=["sim-chips", "sim-scenes"], default="sim-chips")
    p.add_argument("--sizes", type=int, nargs="+", default=[36, 200])
    p.add_argument("--datasets", type=int, default=20, help="small datasets of the largest size")
    p.add_argument("--detectors", nargs="+", default=["region", "os"])
    p.add_argument("--replicates", type=int, default=400)
    p.add_argument("--seed", type=int, default=12345)
    p.add_argument("--out", default="coverage-run")
    p.add_argument("--report", nargs="+", default=None, metavar="FOLDER")
    p.add_argument("--rules", nargs="+", default=["pct", "default"])
    p.add_argument("--compact", action="store_true", help="with --report: one row per cell")
    args = p.parse_args()
    if args.report and args.compact:
        for rule in args.rules:
            print(f"\nrule: {rule}\n")
            compact(args.report, rule)
    elif args.report:
        report(args.report, args.rules)
    else:
        score(args)


if __name__ == "__main__":
    main()
