"""``torchsar-eval make-dataset``: write a dataset into a sharded store (``store:PATH``).

Simulated kinds are generated block by block (item ``i`` depends only on the seed and ``i``),
other datasets are read item by item, so memory does not grow with ``--n``.

The store is built in a hidden ``.<name>.store-partial`` folder beside ``--out``, by a
process holding the lock file ``.<name>.store-lock``, and renamed to ``--out`` when
complete. A second make-dataset into the same ``--out`` is refused while the first runs.
A make-dataset that was killed (SIGKILL, power loss) leaves its partial store behind with
a free lock; the next make-dataset into the same folder removes it. To clean up by hand,
delete ``.<name>.store-partial`` and ``.<name>.store-lock`` while no make-dataset runs.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from pathlib import Path

from torchsar_eval.errors import EvalError

__all__ = ["add_parser", "run", "sim_items"]

SIM = ("sim-chips", "sim-scenes")
"""The simulated kinds, generated block by block (``torchsar.simulate.chips`` / ``scenes``)."""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "make-dataset",
        help="write a dataset (simulated or read from files) into a sharded store",
        description=__doc__.splitlines()[0],
    )
    p.add_argument(
        "--kind", required=True, help="sim-chips, sim-scenes or any dataset spec (e.g. folder:PATH)"
    )
    p.add_argument("--n", type=int, default=None, help="items (default: all / 64 simulated)")
    p.add_argument("--seed", type=int, default=0, help="seed of simulated kinds")
    p.add_argument("--shard-size", type=int, default=1000, help="items per tar shard")
    p.add_argument("--out", type=Path, required=True, help="the new store folder")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run)


def sim_items(kind: str, n: int, seed: int, block: int = 64) -> Iterator[dict]:
    """Simulated items ``0 .. n - 1``, generated ``block`` at a time."""
    import torchsar as ts

    simulate = {"sim-chips": ts.simulate.chips, "sim-scenes": ts.simulate.scenes}[kind]
    for start in range(0, n, block):
        b = simulate(min(block, n - start), seed=seed, start=start)
        for j in range(len(b)):
            item = b[j]
            item["meta"] = {"name": f"{kind}/{start + j}", **item["meta"]}
            yield item


def run(args: argparse.Namespace) -> int:
    from tqdm.auto import tqdm

    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.store import write_store

    if args.n is not None and args.n < 1:
        raise EvalError(f"--n must be >= 1, got {args.n}")
    if args.shard_size < 1:
        raise EvalError(f"--shard-size must be >= 1, got {args.shard_size}")
    if args.out.exists():
        raise EvalError(f"--out {args.out} already exists; choose a new folder")
    if args.kind in SIM:
        n = 64 if args.n is None else args.n
        items = sim_items(args.kind, n, args.seed)
        info = {"source": args.kind, "seed": args.seed}
    else:
        ds = make_dataset(args.kind, n=args.n, seed=args.seed)
        n = len(ds)
        items = (ds[i] for i in range(n))
        info = {"source": args.kind, "options": getattr(ds, "options", {})}
    items = tqdm(items, total=n, desc="make-dataset", disable=args.no_progress, unit="img")
    write_store(items, n, args.out, shard_size=args.shard_size, info=info)
    print(f"wrote {n} items to {args.out} (store:{args.out})")
    return 0
