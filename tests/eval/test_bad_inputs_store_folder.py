"""Crafted bad inputs to stores and folder datasets: each is one clear error (or a warning)
naming the file and field or item, never a traceback, a hang, a huge allocation or a
silently wrong item.

Every case is a row of ``CASES``: a writer that builds the input in ``tmp_path`` and
returns the attempt (a callable), the expected exception or warning type and a pattern
its message must match.
"""

from __future__ import annotations

import io
import json
import os
import re
import signal
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest

from tests.eval.datasets_helpers import write_pair
from tests.io.writers import write_png
from torchsar_eval.cli import main
from torchsar_eval.commands.make_dataset import sim_items
from torchsar_eval.datasets import BadItemError, make_dataset
from torchsar_eval.errors import EvalError
from torchsar_eval.npy import read_npy
from torchsar_eval.store import write_store

N = 4  # items of the crafted stores, two per shard


# --- writers ----------------------------------------------------------------------------


def _store(tmp_path: Path, n: int = N) -> Path:
    """A valid store of ``n`` simulated chips, two per shard."""
    return write_store(sim_items("sim-chips", n, 0), n, tmp_path / "s", shard_size=2)


def _read_all(spec: str):
    """The attempt: build the dataset and read every item."""

    def attempt():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ds = make_dataset(spec)
        return [ds[i] for i in range(len(ds))]

    return attempt


def _header(**changes):
    """A store whose store.json has ``changes`` (a value of ``...`` deletes the key)."""

    def write(tmp_path):
        root = _store(tmp_path)
        head = json.loads((root / "store.json").read_text())
        for k, v in changes.items():
            if v is ...:
                del head[k]
            else:
                head[k] = v
        (root / "store.json").write_text(json.dumps(head))
        return _read_all(f"store:{root}")

    return write


def _store_json_text(text: str):
    def write(tmp_path):
        root = _store(tmp_path)
        (root / "store.json").write_text(text)
        return _read_all(f"store:{root}")

    return write


def _index(change):
    """A store whose index.npy is ``change(index)`` (an array to save, or bytes)."""

    def write(tmp_path):
        root = _store(tmp_path)
        new = change(np.load(root / "index.npy"))
        if isinstance(new, bytes):
            (root / "index.npy").write_bytes(new)
        else:
            np.save(root / "index.npy", new)
        return _read_all(f"store:{root}")

    return write


def _set(index, where, value):
    index[where] = value
    return index


def _swap_rows(index):
    index[[0, 1]] = index[[1, 0]]
    return index


def _fifo_for(name: str):
    """A store whose ``name`` is a FIFO."""

    def write(tmp_path):
        root = _store(tmp_path)
        (root / name).unlink()
        os.mkfifo(root / name)
        return _read_all(f"store:{root}")

    return write


def _missing(name: str):
    def write(tmp_path):
        root = _store(tmp_path)
        (root / name).unlink()
        return _read_all(f"store:{root}")

    return write


def _sparse(name: str, size: int):
    """A store whose ``name`` is a sparse file of ``size`` bytes (no disk used)."""

    def write(tmp_path):
        root = _store(tmp_path)
        with open(root / name, "wb") as f:
            f.truncate(size)
        return _read_all(f"store:{root}")

    return write


def _patch_member(item: int, field: int, edit):
    """A store whose member bytes are replaced by ``edit(bytes)`` (same length)."""

    def write(tmp_path):
        root = _store(tmp_path)
        off, size = (int(v) for v in np.load(root / "index.npy")[item, field])
        shard = root / f"shard-{item // 2:06d}.tar"
        data = bytearray(shard.read_bytes())
        new = edit(bytes(data[off : off + size]))
        assert len(new) == size
        data[off : off + size] = new
        shard.write_bytes(bytes(data))
        return _read_all(f"store:{root}")

    return write


def _legacy(root: Path) -> None:
    """Turn a store into the first store format (no checksums: index rows 0-4 only)."""
    index = np.load(root / "index.npy")[:, :5]
    np.save(root / "index.npy", np.ascontiguousarray(index))
    head = json.loads((root / "store.json").read_text())
    head["version"] = 1
    (root / "store.json").write_text(json.dumps(head))


def _npy(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _legacy_store_without_instances(tmp_path):
    """A store written before checksums whose item 1 lost its instance ids (zeros of the
    same size) while its mask still marks the target."""
    root = _store(tmp_path)
    _legacy(root)
    off, size = (int(v) for v in np.load(root / "index.npy")[1, 2])
    shard = root / "shard-000000.tar"
    data = bytearray(shard.read_bytes())
    zeros = _npy(np.zeros_like(read_npy(bytes(data[off : off + size]))))
    assert len(zeros) == size
    data[off : off + size] = zeros
    shard.write_bytes(bytes(data))
    return _read_all(f"store:{root}")


def _writing_an_item_without_instances(tmp_path):
    """write_store given an item whose mask marks a target that no instance covers."""

    def items():
        for k, it in enumerate(sim_items("sim-chips", 2, 0)):
            if k == 1:
                it["instances"] = it["instances"] * 0
            yield it

    return lambda: write_store(items(), 2, tmp_path / "s")


def _folder(tmp_path: Path) -> Path:
    root = tmp_path / "d"
    lab = np.zeros((16, 16), np.uint8)
    lab[4:7, 4:7] = 1
    write_pair(root, "a", np.full((16, 16), 40), lab)
    return root


def _folder_alias(link):
    """A folder whose ``b.png`` is ``a.png`` again (``link(src, dst)``), with its own mask."""

    def write(tmp_path):
        root = _folder(tmp_path)
        link(root / "a.png", root / "b.png")
        (root / "b.mask.png").write_bytes((root / "a.mask.png").read_bytes())
        return _read_all(f"folder:{root}")

    return write


def _folder_sidecar_fifo(tmp_path):
    root = _folder(tmp_path)
    os.mkfifo(root / "a.spacing.txt")
    return _read_all(f"folder:{root}")


def _folder_sidecar_huge(tmp_path):
    root = _folder(tmp_path)
    with open(root / "a.spacing.txt", "wb") as f:
        f.truncate(64 << 20)  # sparse: 64 MB of NUL bytes, no disk used
    return _read_all(f"folder:{root}")


def _folder_big_blank_image(tmp_path):
    """A 9000 x 9000 PNG of zeros (tens of KB on disk, 81 M pixels decoded)."""
    root = tmp_path / "d"
    root.mkdir()
    blank = np.zeros((9000, 9000), np.uint8)
    write_png(root / "a.png", blank)
    write_png(root / "a.mask.png", blank)
    return _read_all(f"folder:{root}")


def _folder_unlistable_subfolder(tmp_path):
    """A subfolder that cannot be listed (permissions; simulated, as root may list all)."""
    root = _folder(tmp_path)
    write_pair(root / "locked", "b", np.full((16, 16), 40), np.zeros((16, 16)))
    scandir = os.scandir

    def denied(path="."):
        if Path(path).name == "locked":
            raise PermissionError(13, "Permission denied", str(path))
        return scandir(path)

    def attempt():
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(os, "scandir", denied)
            return _read_all(f"folder:{root}")()

    return attempt


def _folder_fractional_n(tmp_path):
    root = _folder(tmp_path)
    return lambda: make_dataset(f"folder:{root}", n=2.5)


def _datasets_sharing_a_file(tmp_path):
    """Two folder datasets that reach the same image through different paths."""
    root = _folder(tmp_path)
    (root / "sub").mkdir()
    from torchsar_eval.datasets.files import warn_shared_files

    def attempt():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            named = {
                "A": make_dataset(f"folder:{root}"),
                "B": make_dataset(f"folder:{root / 'sub' / '..'}"),
            }
        warn_shared_files(named)

    return attempt


def test_evaluate_warns_when_two_datasets_read_one_image(tmp_path):
    from torchsar_eval import evaluate
    from torchsar_eval.datasets.files import SharedFilesWarning

    root = _folder(tmp_path)
    (root / "sub").mkdir()
    specs = [f"folder:{root}?type=intensity", f"folder:{root / 'sub' / '..'}?type=intensity"]
    with pytest.warns(SharedFilesWarning, match="both read"):
        evaluate(specs, ["ca"], progress=False)


# --- the table ----------------------------------------------------------------------------

SHARD0, SHARD1, INDEX, HEAD = (
    r"shard-000000\.tar",
    r"shard-000001\.tar",
    r"index\.npy",
    r"store\.json",
)

CASES = [
    # store.json
    ("n smaller than the index", _header(n=2), EvalError, rf"{HEAD}: n=2 but {INDEX} has 4 rows"),
    ("n larger than the index", _header(n=8), EvalError, rf"{HEAD}: n=8 but {INDEX} has 4 rows"),
    ("n negative", _header(n=-5), EvalError, rf"{HEAD}: n=-5 must be a whole number >= 0"),
    ("n a string", _header(n="abc"), EvalError, rf"{HEAD}: n='abc' must be a whole number"),
    ("n a float", _header(n=2.5), EvalError, rf"{HEAD}: n=2.5 must be a whole number"),
    ("n huge", _header(n=10**12), EvalError, rf"{HEAD}: n=1000000000000 but {INDEX} has 4"),
    ("n missing", _header(n=...), EvalError, rf"{HEAD}: n is missing"),
    ("shard_size zero", _header(shard_size=0), EvalError, rf"{HEAD}: shard_size=0 must be"),
    ("shard_size wrong", _header(shard_size=3), EvalError, rf"{INDEX}: rows 0 and 2 .*{SHARD0}"),
    ("store.json not JSON", _store_json_text("{'n': 4,"), EvalError, rf"{HEAD}: not valid JSON"),
    ("store.json a list", _store_json_text("[1, 2]"), EvalError, rf"{HEAD}: .*JSON object.*list"),
    ("store.json deep", _store_json_text("[" * 100000), EvalError, rf"{HEAD}: not valid JSON"),
    ("store.json huge", _sparse("store.json", 64 << 20), EvalError, rf"{HEAD}: .*bytes"),
    ("store.json a FIFO", _fifo_for("store.json"), EvalError, rf"{HEAD}: is not a regular file"),
    # index.npy
    (
        "duplicated index row",
        _index(lambda x: _set(x, 3, x[2])),
        EvalError,
        rf"{INDEX}: rows 2 and 3 point to the same bytes of {SHARD1}",
    ),
    (
        "offset beyond the tar",
        _index(lambda x: _set(x, (1, 0, 0), 10**13)),
        EvalError,
        rf"{INDEX}: row 1 .*past the end of {SHARD0}",
    ),
    (
        "size beyond the tar",
        _index(lambda x: _set(x, (1, 4, 1), 10**13)),
        EvalError,
        rf"{INDEX}: row 1 .*past the end of {SHARD0}",
    ),
    ("negative offset", _index(lambda x: _set(x, (0, 0, 0), -512)), EvalError, rf"{INDEX}: row 0"),
    (
        "offsets overflowing",
        _index(lambda x: _set(x, (0, 4), (2**62, 2**62))),
        EvalError,
        rf"{INDEX}: row 0",
    ),
    (
        "swapped rows",
        _index(_swap_rows),
        BadItemError,
        rf"{SHARD0}: item 000000000: .*000000001\.image\.npy",
    ),
    ("index wrong shape", _index(lambda x: x[:, :3]), EvalError, rf"{INDEX}: .*shape"),
    ("index not npy", _index(lambda x: b"garbage" * 20), EvalError, rf"{INDEX}: not a \.npy file"),
    ("index a FIFO", _fifo_for("index.npy"), EvalError, rf"{INDEX}: is not a regular file"),
    ("index missing", _missing("index.npy"), EvalError, rf"{INDEX}: .*(missing|no such)"),
    # shards
    ("shard a FIFO", _fifo_for("shard-000001.tar"), EvalError, rf"{SHARD1}: is not a regular"),
    ("shard missing", _missing("shard-000001.tar"), EvalError, rf"{SHARD1}: .*missing"),
    (
        "npy magic changed",
        _patch_member(0, 0, lambda b: b"X" + b[1:]),
        BadItemError,
        rf"{SHARD0}: item 000000000",
    ),
    (
        "image byte flipped",
        _patch_member(1, 0, lambda b: b[:-1] + bytes([b[-1] ^ 0x40])),
        BadItemError,
        rf"{SHARD0}: item 000000001: .*checksum",
    ),
    (
        "json broken",
        _patch_member(0, 4, lambda b: b"[" + b[1:]),
        BadItemError,
        rf"{SHARD0}: item 000000000",
    ),
    # item contract: a target no instance covers
    (
        "legacy store: instances lost",
        _legacy_store_without_instances,
        BadItemError,
        rf"{SHARD0}: item 000000001: mask marks \d+ target pixels that no instance covers",
    ),
    (
        "write: instances lost",
        _writing_an_item_without_instances,
        EvalError,
        r"item 1 .*mask marks \d+ target pixels that no instance covers",
    ),
    # folder datasets
    (
        "spacing sidecar a FIFO",
        _folder_sidecar_fifo,
        BadItemError,
        r"a\.spacing\.txt: is not a regular file",
    ),
    (
        "spacing sidecar huge",
        _folder_sidecar_huge,
        BadItemError,
        r"a\.spacing\.txt: .*bytes.*expected",
    ),
    (
        "image reached by a symlink",
        _folder_alias(os.symlink),
        EvalError,
        r"b\.png is the same file as .*a\.png",
    ),
    (
        "image reached by a hard link",
        _folder_alias(os.link),
        EvalError,
        r"b\.png is the same file as .*a\.png",
    ),
    (
        "9000x9000 blank image",
        _folder_big_blank_image,
        BadItemError,
        r"a\.png: .*9000x9000.*max_pixels=\d+",
    ),
    (
        "unlistable subfolder",
        _folder_unlistable_subfolder,
        EvalError,
        r"cannot list folder .*locked \(Permission denied\)",
    ),
    ("n of 2.5 items", _folder_fractional_n, EvalError, r"n=2\.5: must be a whole number"),
    (
        "datasets sharing files",
        _datasets_sharing_a_file,
        UserWarning,
        r"datasets A and B both read .*a\.png",
    ),
]


@pytest.fixture
def fifo_watchdog(tmp_path):
    """If the code under test blocks opening a FIFO of ``tmp_path``, unblock it after a few
    seconds (the reader then sees an empty file), so a hang fails the test instead."""
    stop = threading.Event()

    def watch():
        if stop.wait(10):
            return
        while not stop.is_set():
            for p in tmp_path.rglob("*"):
                try:
                    fd = os.open(p, os.O_WRONLY | os.O_NONBLOCK)
                except OSError:  # not a FIFO, or nobody waits on it
                    continue
                os.close(fd)
            stop.wait(0.2)

    t = threading.Thread(target=watch, daemon=True)
    t.start()
    yield
    stop.set()
    t.join()


@pytest.mark.parametrize(
    ("writer", "kind", "pattern"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_input_is_one_clear_error(tmp_path, fifo_watchdog, writer, kind, pattern):
    attempt = writer(tmp_path)
    if issubclass(kind, Warning):
        with pytest.warns(kind, match=pattern):
            attempt()
    else:
        with pytest.raises(kind, match=pattern) as info:
            attempt()
        assert "\n" not in str(info.value)


# --- the command line: exit 2, one line on stderr ----------------------------------------


def _one_error_line(capsys) -> str:
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1, lines
    assert lines[0].startswith("torchsar-eval: error: ")
    return lines[0]


@pytest.mark.parametrize(
    ("writer", "pattern"),
    [
        (_store_json_text("[1, 2]"), rf"{HEAD}: .*JSON object"),
        (_index(lambda x: _set(x, (1, 0, 0), 10**13)), rf"{INDEX}: row 1 .*past the end"),
        (_index(lambda x: _set(x, 3, x[2])), rf"{INDEX}: rows 2 and 3"),
    ],
    ids=["store.json a list", "offset beyond the tar", "duplicated index row"],
)
def test_run_on_a_bad_store_exits_2_with_one_line(tmp_path, capsys, writer, pattern):
    writer(tmp_path)
    argv = [
        "run",
        "--dataset",
        f"store:{tmp_path / 's'}",
        "--detectors",
        "ca",
        "--out",
        str(tmp_path / "out"),
        "--no-progress",
    ]
    assert main(argv) == 2
    assert re.search(pattern, _one_error_line(capsys))


# --- make-dataset: concurrent writers and killed ones -------------------------------------

HOLD = """
import sys
from torchsar_eval.locks import hold
with hold(sys.argv[1]):
    print("held", flush=True)
    sys.stdin.read()
"""


def test_make_dataset_while_another_writes_the_same_out(tmp_path, capsys, monkeypatch):
    import torchsar_eval.store as store

    monkeypatch.setattr(store, "LOCK_WAIT_S", 0.2)
    out = tmp_path / "s"
    lock = store.lock_path(out)
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(lock)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "held"
        argv = [
            "make-dataset",
            "--kind",
            "sim-chips",
            "--n",
            "2",
            "--out",
            str(out),
            "--no-progress",
        ]
        assert main(argv) == 2
        assert "is being written by another make-dataset" in _one_error_line(capsys)
        assert not out.exists()
    finally:
        proc.stdin.close()
        proc.wait()


KILLED = """
import sys, time
from torchsar_eval.commands.make_dataset import sim_items
from torchsar_eval.store import write_store

def items():
    for k, it in enumerate(sim_items("sim-chips", 4, 0)):
        if k == 2:
            print("writing", flush=True)
            time.sleep(600)
        yield it

write_store(items(), 4, sys.argv[1], shard_size=1)
"""


@pytest.mark.integration
def test_a_killed_make_dataset_leaves_a_partial_store_the_next_one_removes(tmp_path):
    import torchsar_eval.store as store

    out = tmp_path / "s"
    proc = subprocess.Popen(
        [sys.executable, "-c", KILLED, str(out)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout.readline().strip() == "writing"
        partial = store.partial_path(out)
        assert partial.is_dir() and any(partial.iterdir())
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert partial.is_dir()  # left by the dead writer ...
    other = tmp_path / "t"
    write_store(sim_items("sim-chips", 1, 0), 1, other)  # ... removed by the next writer
    assert not partial.exists() and not store.lock_path(out).exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t"]
    write_store(sim_items("sim-chips", 1, 0), 1, out)  # and the name is free again
    assert (out / "store.json").is_file()
