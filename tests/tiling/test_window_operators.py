"""Tiled == untiled for every window CFAR and every speckle filter, over several tilings
(tiles not dividing the scene, tiles as small as the footprint, one tile per scene)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.tiling._scenes import scene
from torchsar.speckle import FILTERS
from torchsar.tiling import DETECTORS, iter_tiles, run_scene

H, W = 61, 75
TILINGS = [7, (25, 30)]  # the footprint's side; a tile not dividing the scene
MORE_TILINGS = [(9, 16), (61, 75), (100, 100)]  # slow: uneven, exactly one, larger
CFAR_OPTS = {"guard": 1, "train": 2}  # reach 3: footprint 7 x 7


@pytest.fixture(scope="module")
def x() -> np.ndarray:
    return scene(H, W, seed=3, seams=(9, 16))


def _untiled(fn, x: np.ndarray, **kw):
    return fn(torch.from_numpy(x)[None, None], **kw)


@pytest.mark.parametrize("more", [False, pytest.param(True, marks=pytest.mark.slow)])
@pytest.mark.parametrize("name", sorted(DETECTORS))
def test_every_window_cfar(name, more, x):
    full = _untiled(DETECTORS[name], x, **CFAR_OPTS)
    want_mask = full.mask[0, 0].numpy()
    assert want_mask.any() and not want_mask.all()  # a non-trivial comparison
    for tile in MORE_TILINGS if more else TILINGS:
        got = run_scene(x, name, tile=tile, batch=3, **CFAR_OPTS)
        np.testing.assert_array_equal(got["mask"], want_mask, err_msg=f"{name} tile={tile}")
        np.testing.assert_allclose(
            got["statistic"], full.statistic[0, 0].numpy(), rtol=1e-6, atol=1e-6
        )


@pytest.mark.parametrize("more", [False, pytest.param(True, marks=pytest.mark.slow)])
@pytest.mark.parametrize("name", sorted(FILTERS))
def test_every_speckle_filter(name, more, x):
    want = _untiled(FILTERS[name], x, window=7)[0, 0].numpy()
    for tile in MORE_TILINGS if more else TILINGS:
        got = run_scene(x, name, tile=tile, batch=2, window=7)["image"]
        np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-6, err_msg=f"tile={tile}")


def test_results_do_not_depend_on_batch_or_a_wider_halo(x):
    one = run_scene(x, "os", tile=(12, 20), batch=1, **CFAR_OPTS)
    many = run_scene(x, "os", tile=(12, 20), batch=7, **CFAR_OPTS)
    wide = run_scene(x, "os", tile=(12, 20), halo=9, batch=4, **CFAR_OPTS)
    for r in (many, wide):
        np.testing.assert_array_equal(r["mask"], one["mask"])
        np.testing.assert_array_equal(r["statistic"], one["statistic"])


def test_float64_scene_stays_float64_and_matches(x):
    x64 = x.astype(np.float64)
    full = _untiled(DETECTORS["vi"], x64, **CFAR_OPTS)
    got = run_scene(x64, "vi", tile=13, **CFAR_OPTS)
    assert got["statistic"].dtype == np.float64
    np.testing.assert_array_equal(got["mask"], full.mask[0, 0].numpy())
    # float64 window sums from another origin (the window): equal to rounding
    np.testing.assert_allclose(got["statistic"], full.statistic[0, 0].numpy(), rtol=1e-9)


def test_outputs_into_caller_arrays(tmp_path, x):
    mask = np.lib.format.open_memmap(tmp_path / "m.npy", "w+", bool, x.shape)
    stat = np.lib.format.open_memmap(tmp_path / "s.npy", "w+", np.float32, x.shape)
    got = run_scene(x, "ca", tile=20, out={"mask": mask, "statistic": stat}, **CFAR_OPTS)
    assert got["mask"] is mask and got["statistic"] is stat
    full = _untiled(DETECTORS["ca"], x, **CFAR_OPTS)
    np.testing.assert_array_equal(np.asarray(mask), full.mask[0, 0].numpy())


def test_every_tile_is_yielded_once_and_cores_partition_the_scene(x):
    seen = np.zeros(x.shape, int)
    for t, res in iter_tiles(x, "so", tile=(10, 21), **CFAR_OPTS):
        seen[t.core] += 1
        assert res["mask"].shape == seen[t.core].shape
    assert (seen == 1).all()


def test_ac_scene_clutter_mean_is_the_whole_image_estimate(x):
    from torchsar.cfar.ac import ac, global_censor_threshold
    from torchsar.errors import OptionError
    from torchsar.tiling.plan import plan_tiles
    from torchsar.tiling.run import scene_clutter_mean
    from torchsar.tiling.source import as_scene

    t = torch.from_numpy(x)[None, None]
    mu, _ = global_censor_threshold(t, 1e-3, iterations=3)
    streamed = scene_clutter_mean(as_scene(x), plan_tiles(x.shape, (10, 17), 0), 1e-3, 3)
    assert streamed == pytest.approx(mu.item(), rel=1e-12)
    given = ac(t, guard=1, train=2, clutter_mean=mu.item())
    own = ac(t, guard=1, train=2)
    assert torch.equal(given.statistic, own.statistic)
    with pytest.raises(OptionError, match="clutter_mean"):
        ac(t, clutter_mean=-1.0)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    h=st.integers(5, 40),
    w=st.integers(5, 40),
    th=st.integers(5, 30),
    tw=st.integers(5, 30),
    name=st.sampled_from(["ca", "go", "two_parameter", "lee"]),
)
def test_any_tiling_of_any_scene(seed, h, w, th, tw, name):
    x = np.random.default_rng(seed).exponential(size=(h, w)).astype(np.float32)
    opts = {"guard": 0, "train": 2} if name != "lee" else {"window": 5}
    got = run_scene(x, name, tile=(th, tw), **opts)
    fn = DETECTORS.get(name) or FILTERS[name]
    full = _untiled(fn, x, **opts)
    if name == "lee":
        np.testing.assert_allclose(got["image"], full[0, 0].numpy(), rtol=2e-6, atol=1e-6)
    else:
        np.testing.assert_array_equal(got["mask"], full.mask[0, 0].numpy())
        np.testing.assert_allclose(got["statistic"], full.statistic[0, 0].numpy(), rtol=1e-6)


class _Recorded:
    """A scene that records the thread of every read."""

    def __init__(self, data: np.ndarray) -> None:
        self.data, self.shape, self.dtype = data, data.shape, data.dtype
        self.threads: list[str] = []

    def __getitem__(self, key):
        import threading

        self.threads.append(threading.current_thread().name)
        return self.data[key]


def test_windows_are_read_ahead_on_a_second_thread_and_change_nothing():
    x = scene(150, 170, seed=11)
    rec = _Recorded(x)
    got = list(iter_tiles(rec, "ca", tile=48, batch=2))
    want = list(iter_tiles(x, "ca", tile=48, batch=2))
    assert len(got) == len(want) > 4
    for (ta, a), (tb, b) in zip(got, want, strict=True):
        assert ta == tb and a.keys() == b.keys()
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])
    assert rec.threads and all(t.startswith("torchsar-read") for t in rec.threads)


def test_a_bad_window_read_ahead_fails_when_its_turn_comes():
    """A window that fails to read raises its own error from the iteration, after the
    tiles before it were yielded, whichever thread read it."""
    from torchsar.errors import InputValueError

    x = scene(150, 150, seed=12)
    order = [t.index for t, _ in iter_tiles(x, "ca", tile=48, batch=1)]
    x[75, 75] = np.nan  # in the middle tile's window only (and the halos beside it)
    seen = []
    with pytest.raises(InputValueError, match="finite"):
        for t, _ in iter_tiles(_Recorded(x), "ca", tile=48, batch=1):  # read lazily
            seen.append(t.index)
    assert seen == order[: len(seen)] and 0 < len(seen) < len(order)


def test_windows_are_staged_as_the_batch_they_make():
    """On CUDA the batch is copied once, straight into page-locked memory
    (``stack_into``): the same tensor ``to_batch`` stacks, for every dtype a scene has."""
    from torchsar.tiling.footprint import to_batch
    from torchsar.tiling.run import stack_into

    gen = np.random.default_rng(5)
    for dtype in (np.float32, np.float64, np.uint16):
        windows = [(gen.random((6, 7)) * 100).astype(dtype) for _ in range(3)]
        want = to_batch(windows, None)
        got = stack_into(windows, torch.empty(want.shape, dtype=want.dtype))
        assert torch.equal(got, want)
