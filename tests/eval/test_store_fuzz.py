"""Fuzzing stores: a valid store written by ``write_store``, then its header, index and tar
shards mutated at random (seeded). Contract: every mutated store opens and reads items
equal to the ones written, or raises an EvalError naming a file of the store; never
another exception. A store of the first format (no checksums) cannot tell changed data
bytes, so there the contract is a *valid* item or the error: arrays that keep the item
contract (dtypes, shapes, a finite non-negative image, the mask exactly the instances'
pixels) and, where the meta has them, a box and a class for each instance id.

``python -m tests.eval.test_store_fuzz [CASES] [SEED]`` prints the outcome counts.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import traceback
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import torch

from torchsar_eval.errors import EvalError
from torchsar_eval.store import StoreDataset, write_store

N_ITEMS = 5
SHARD_SIZE = 2
FIELDS = ("image", "mask", "instances", "ignore")


def _items(seed: int) -> list[dict]:
    """Small items that keep the item contract: targets as boxes of instance ids."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(N_ITEMS):
        c, h, w = (1 + i % 2, 6 + i, 10)
        inst = np.zeros((c, h, w), np.int32)
        boxes = []
        for k in range(1 + i % 3):
            r, col = int(rng.integers(0, h - 2)), 3 * k + int(rng.integers(2))
            inst[0, r : r + 2, col : col + 2] = k + 1
        for k in range(int(inst.max())):
            rr, cc = np.nonzero(inst[0] == k + 1)
            boxes.append([int(rr.min()), int(cc.min()), int(rr.max()) + 1, int(cc.max()) + 1])
        ignore = np.zeros((c, h, w), bool)
        ignore[:, -1, :] = inst[:, -1, :] == 0
        meta = {
            "name": f"item{i}",
            "classes": ["ship"] * len(boxes),
            "boxes": boxes,
            "gt": "mask",
            "class": None,
            "pixel_spacing": [0.5, 0.5],
            "sample_type": "intensity",
        }
        out.append(
            {
                "image": torch.from_numpy(rng.exponential(1.0, (c, h, w)).astype(np.float32)),
                "mask": torch.from_numpy(inst > 0),
                "instances": torch.from_numpy(inst),
                "ignore": torch.from_numpy(ignore),
                "meta": meta,
            }
        )
    return out


INTERESTING = [0, 1, -1, 2, 511, 512, 513, -512, 2**31, 2**32, 2**62, -(2**63), 10**13]
JSON_VALUES = [-5, 0, 1, 3, 10**12, "abc", None, [], {}, 2.5, True, "4", -(2**70)]


def _mutate_header(root: Path, rng) -> str:
    path = root / "store.json"
    text = path.read_text(errors="replace")
    kind = rng.integers(5)
    try:
        head = json.loads(text)
    except ValueError:
        head = None
    if not isinstance(head, dict) or not head:
        kind = 4  # an earlier mutation broke the JSON: flip bytes instead
    if kind == 0:
        key = str(rng.choice(["n", "shard_size", "version", "format", "fields", "source"]))
        head[key] = JSON_VALUES[rng.integers(len(JSON_VALUES))]
        path.write_text(json.dumps(head))
        return f"header {key}={head[key]!r}"
    if kind == 1:
        key = str(rng.choice(list(head)))
        del head[key]
        path.write_text(json.dumps(head))
        return f"header del {key}"
    if kind == 2:
        cut = int(rng.integers(len(text) + 1))
        path.write_text(text[:cut])
        return f"header cut {cut}"
    if kind == 3:
        path.write_text(json.dumps(JSON_VALUES[rng.integers(len(JSON_VALUES))]))
        return "header replaced"
    data = bytearray(path.read_bytes()) or bytearray(b" ")
    pos = int(rng.integers(len(data)))
    data[pos] ^= 1 << int(rng.integers(8))
    path.write_bytes(bytes(data))
    return f"header flip {pos}"


def _mutate_index(root: Path, rng) -> str:
    path = root / "index.npy"
    kind = rng.integers(7)
    try:
        index = np.load(path)
    except Exception:  # numpy's own complaints about a broken file: any type
        kind = 6  # an earlier mutation broke the file: flip bytes instead
    if kind < 5 and (index.ndim != 3 or index.dtype != np.int64 or len(index) == 0):
        kind = 6
    if kind == 0:
        where = tuple(int(rng.integers(s)) for s in index.shape)
        value = INTERESTING[rng.integers(len(INTERESTING))]
        index[where] = np.int64(value) if value < 2**63 else 0
        np.save(path, index)
        return f"index {where}={value}"
    if kind == 1:
        where = tuple(int(rng.integers(s)) for s in index.shape)
        index[where] += int(rng.choice([-1, 1, -512, 512, 1024]))
        np.save(path, index)
        return f"index {where} nudged"
    if kind == 2:
        a, b = (int(v) for v in rng.integers(len(index), size=2))
        index[b] = index[a]
        np.save(path, index)
        return f"index row {b} = row {a}"
    if kind == 3:
        a, b = (int(v) for v in rng.integers(len(index), size=2))
        index[[a, b]] = index[[b, a]]
        np.save(path, index)
        return f"index rows {a}, {b} swapped"
    if kind == 4:
        np.save(
            path,
            [
                index[:-1],
                index.astype(np.int32),
                index.astype(float),
                index[:, :3],
                index.reshape(-1),
            ][int(rng.integers(5))],
        )
        return "index reshaped"
    data = bytearray(path.read_bytes()) or bytearray(b"\0")
    if kind == 5:
        cut = int(rng.integers(len(data)))
        path.write_bytes(bytes(data[:cut]))
        return f"index cut {cut}"
    pos = int(rng.integers(len(data)))
    data[pos] ^= 1 << int(rng.integers(8))
    path.write_bytes(bytes(data))
    return f"index flip {pos}"


def _mutate_shard(root: Path, rng) -> str:
    shards = sorted(root.glob("shard-*.tar"))
    if not shards:
        return "no shard left"
    path = shards[int(rng.integers(len(shards)))]
    data = bytearray(path.read_bytes()) or bytearray(b"\0")
    kind = rng.integers(6)
    if kind <= 2:  # flips: anywhere, or in the first kilobytes (headers, npy headers)
        pos = int(rng.integers(len(data) if kind == 0 else min(len(data), 4096)))
        data[pos] ^= 1 << int(rng.integers(8))
        path.write_bytes(bytes(data))
        return f"{path.name} flip {pos}"
    if kind == 3:
        cut = int(rng.integers(len(data)))
        path.write_bytes(bytes(data[:cut]))
        return f"{path.name} cut {cut}"
    if kind == 4:
        block = int(rng.integers(max(1, len(data) // 512))) * 512
        data[block : block + 512] = bytes(512)
        path.write_bytes(bytes(data))
        return f"{path.name} zero block {block}"
    path.unlink()
    return f"{path.name} removed"


def _legacy(root: Path) -> None:
    """The first store format: no checksums (index rows 0-4), version 1."""
    np.save(root / "index.npy", np.ascontiguousarray(np.load(root / "index.npy")[:, :5]))
    head = json.loads((root / "store.json").read_text())
    head["version"] = 1
    (root / "store.json").write_text(json.dumps(head))


def _valid(item: dict) -> bool:
    """The item contract that holds without a checksum (see the module docstring)."""
    image, mask, inst, ignore = (item[k] for k in FIELDS)
    k = int(inst.max())
    meta = item["meta"]
    return (
        image.dtype == torch.float32
        and image.ndim == 3
        and min(image.shape) >= 1
        and mask.dtype == ignore.dtype == torch.bool
        and inst.dtype == torch.int32
        and image.shape == mask.shape == inst.shape == ignore.shape
        and torch.equal(mask, inst > 0)
        and bool(torch.isfinite(image).all())
        and bool((image >= 0).all())
        and isinstance(meta, dict)
        and all(
            isinstance(v := meta.get(key, [None] * k), list) and len(v) >= k
            for key in ("boxes", "classes")
        )
        and meta.get("gt", "mask") in ("mask", "box")
    )


def _same(a: dict, b: dict) -> bool:
    return all(torch.equal(a[k], b[k]) for k in FIELDS) and a["meta"] == b["meta"]


def _outcome(root: Path, expected: list[dict], legacy: bool) -> str:
    """``same``, ``valid`` (legacy: an item that keeps the contract), ``error`` (an
    EvalError naming a store file), or what broke the contract."""
    names = ("store.json", "index.npy", "shard-", str(root))
    try:
        ds = StoreDataset(root)
        got = [ds[i] for i in range(min(len(ds), N_ITEMS + 1))]
    except EvalError as exc:
        return "error" if any(n in str(exc) for n in names) else f"unnamed error: {exc}"
    except Exception as exc:  # the contract forbids it: name the type and where
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        return f"crash: {type(exc).__name__} at {Path(frame.filename).name}:{frame.lineno}"
    if len(got) != len(expected):
        return f"wrong length {len(got)}"
    if all(_same(g, e) for g, e in zip(got, expected, strict=True)):
        return "same"
    if not all(map(_valid, got)):
        return "invalid item"
    return "valid" if legacy else "changed item"


def fuzz(cases: int, seed: int = 0, examples: dict | None = None) -> Counter:
    """Outcome counts of ``cases`` mutated stores (seeded; same seed, same cases);
    ``examples`` (if given) gets the mutations of the first case of each outcome."""
    expected = _items(seed)
    counts: Counter = Counter()
    with tempfile.TemporaryDirectory() as tmp:
        base = write_store(iter(expected), N_ITEMS, Path(tmp) / "base", shard_size=SHARD_SIZE)
        expected = [StoreDataset(base)[i] for i in range(N_ITEMS)]  # as stored (meta via JSON)
        for case in range(cases):
            rng = np.random.default_rng([seed, case])
            root = Path(tmp) / f"case{case}"
            shutil.copytree(base, root)
            legacy = bool(rng.random() < 0.25)
            if legacy:
                _legacy(root)
            done = ["legacy"] if legacy else []
            for _ in range(int(rng.integers(1, 4))):
                mutate = (_mutate_header, _mutate_index, _mutate_shard)[int(rng.integers(3))]
                done.append(mutate(root, rng))
            outcome = _outcome(root, expected, legacy)
            counts[outcome] += 1
            if examples is not None:
                examples.setdefault(outcome, f"case {case}: {'; '.join(done)}")
            shutil.rmtree(root)
    return counts


def _bad(counts: Counter) -> dict:
    return {k: v for k, v in counts.items() if k not in ("same", "valid", "error")}


@pytest.mark.integration  # fuzz
def test_mutated_stores_read_back_the_same_items_or_name_the_file():
    counts = fuzz(800, seed=1)
    assert not _bad(counts), counts
    assert counts["error"] > 400 and counts["same"] > 0  # the mutations did bite, not all


@pytest.mark.slow
def test_mutated_stores_long():
    counts = fuzz(20000, seed=2)
    assert not _bad(counts), counts


if __name__ == "__main__":
    n, s = (int(a) for a in [*sys.argv[1:], "800", "1"][:2])
    seen: dict = {}
    result = fuzz(n, s, seen)
    for k, v in result.most_common():
        print(f"{v:6d}  {k}    e.g. {seen[k]}")
    print(f"{sum(result.values())} cases, {len(_bad(result))} distinct contract failures")
