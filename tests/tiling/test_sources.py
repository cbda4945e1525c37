"""Every kind of scene source gives the same result: tensor, array, memmap, a windowed
reader (reads only the windows asked for), integer scenes."""

from __future__ import annotations

import numpy as np
import torch

from tests.tiling._scenes import reference_objects, same_objects
from torchsar import cfar
from torchsar.tiling import run_scene, scene_objects

X = np.random.default_rng(1).exponential(size=(45, 52)).astype(np.float32)
X[20, 20] = 200.0


class Reader:
    """A windowed reader: shape, dtype and (slice, slice) reads; records the reads."""

    def __init__(self, data: np.ndarray) -> None:
        self._data, self.shape, self.dtype, self.reads = data, data.shape, data.dtype, []

    def __getitem__(self, key):
        rows, cols = key
        self.reads.append((rows.stop - rows.start) * (cols.stop - cols.start))
        return self._data[rows, cols].copy()


def test_sources_agree(tmp_path):
    want = run_scene(X, "go", tile=16, guard=1, train=2)
    mm = np.lib.format.open_memmap(tmp_path / "x.npy", "w+", np.float32, X.shape)
    mm[:] = X
    reader = Reader(X)
    for src in (torch.from_numpy(X), mm, reader):
        got = run_scene(src, "go", tile=16, guard=1, train=2)
        np.testing.assert_array_equal(got["mask"], want["mask"])
        np.testing.assert_array_equal(got["statistic"], want["statistic"])
    assert max(reader.reads) == (16 + 6) ** 2  # one window at a time, never the scene


def test_integer_scene_reads_as_float32():
    q = np.round(X * 10).astype(np.uint16)
    got = run_scene(q, "ca", tile=20, guard=1, train=2)
    want = run_scene(q.astype(np.float32), "ca", tile=20, guard=1, train=2)
    assert got["statistic"].dtype == np.float32
    np.testing.assert_array_equal(got["statistic"], want["statistic"])


def test_a_tiff_scene_reader(tmp_path):
    from torchsar.io.tiff_scene import TiffScene
    from torchsar.simulate.scene_file import write_scene_file

    sf = write_scene_file(tmp_path / "s.tif", shape=(300, 260), tile=64, n_targets=6)
    with TiffScene(sf.path, as_intensity=True) as r:  # a windowed reader of the io package
        whole = r[0:300, 0:260]
        got = scene_objects(r, "ca", tile=(100, 90), pfa=1e-5)
    full = cfar.ca(torch.from_numpy(whole)[None, None], pfa=1e-5)
    want = reference_objects(full.mask[0, 0].numpy(), full.statistic[0, 0].numpy())
    assert len(want) >= 6
    same_objects(got, want)
