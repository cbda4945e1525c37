"""Signal-to-clutter ratio: the ring measurement against a pixel-by-pixel reference, the
bins, the Wilson interval against its definition, the additive state, the simulator's known
SCR, and Pd versus SCR of CA-CFAR against the textbook curve."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import torch

import torchsar as ts
import torchsar_eval as te
from torchsar.metrics import Matching
from torchsar.metrics.scr import SCR_NAMES, scr_bins, scr_rows, target_scr_db, wilson
from torchsar.objects import ObjectRules


def _slow_scr(image, ids, ignore, guard, width):
    """Per target: mean over its pixels / mean over every clutter pixel whose Chebyshev
    distance to the target's bounding box is in ``(guard, guard + width]``, pixel by pixel."""
    out = []
    for k in range(1, int(ids.max()) + 1):
        p = int(np.flatnonzero((ids == k).any(axis=(1, 2)))[0])
        rows, cols = np.nonzero(ids[p] == k)
        r0, r1, c0, c1 = rows.min(), rows.max(), cols.min(), cols.max()
        ring = []
        for r in range(ids.shape[1]):
            for c in range(ids.shape[2]):
                d = max(r0 - r, r - r1, c0 - c, c - c1, 0)
                if guard < d <= guard + width and ids[p, r, c] == 0 and not ignore[p, r, c]:
                    ring.append(image[p, r, c])
        target = image[p][ids[p] == k].mean()
        out.append(10 * math.log10(target / np.mean(ring)) if ring else math.nan)
    return np.array(out)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scr_equals_the_pixel_by_pixel_ring(seed):
    rng = np.random.default_rng(seed)
    n, h, w = 2, 40, 48
    image = rng.exponential(size=(n, h, w))
    ids = np.zeros((n, h, w), np.int64)
    k = 0
    for p in range(n):
        for _ in range(rng.integers(1, 4)):
            r, c = rng.integers(-2, h - 3), rng.integers(-2, w - 3)  # some cut by the edge
            k += 1
            ids[p, max(r, 0) : r + rng.integers(2, 7), max(c, 0) : c + rng.integers(2, 7)] = k
            image[p][ids[p] == k] *= 30.0
    ids = np.unique(ids, return_inverse=True)[1].reshape(ids.shape)  # later ones overwrite
    ignore = (rng.random((n, h, w)) < 0.1) & (ids == 0)
    g = int(ids.max())
    plane = np.array([np.flatnonzero((ids == i).any(axis=(1, 2)))[0] for i in range(1, g + 1)])
    box = np.array(
        [
            [*np.argwhere(ids == i)[:, 1:].min(0), *(np.argwhere(ids == i)[:, 1:].max(0) + 1)]
            for i in range(1, g + 1)
        ],
        dtype=float,
    )
    for guard, width in ((3, 8), (0, 2), (1, 30)):
        got = target_scr_db(image, ids, ignore, box, plane, guard=guard, width=width)
        np.testing.assert_allclose(got, _slow_scr(image, ids, ignore, guard, width), rtol=1e-12)


def test_scr_is_nan_without_clutter_and_infinite_without_clutter_power():
    ids = np.ones((1, 6, 6), np.int64)  # the target fills the image: no ring
    box = np.array([[0, 0, 6, 6.0]])
    assert np.isnan(target_scr_db(np.ones((1, 6, 6)), ids, ids < 0, box, np.zeros(1, int)))[0]
    ids = np.zeros((1, 16, 16), np.int64)
    ids[0, 7, 7] = 1
    img = ids.astype(float)  # zero clutter
    box = np.array([[7, 7, 8, 8.0]])
    assert target_scr_db(img, ids, ids < 0, box, np.zeros(1, int))[0] == np.inf
    assert np.isnan(target_scr_db(img * 0, ids, ids < 0, box, np.zeros(1, int))[0])


def test_bins_are_half_open_and_named():
    edges = [-0.01, 0.0, 4.99, 5.0, 19.99, 20.0, 1e9, -1e9]
    assert [SCR_NAMES[b] for b in scr_bins(np.array(edges))] == [
        "<0",
        "0-5",
        "0-5",
        "5-10",
        "15-20",
        ">=20",
        ">=20",
        "<0",
    ]
    assert SCR_NAMES[scr_bins(np.array([np.nan]))[0]] == "n/a"


@pytest.mark.parametrize("k,n", [(0, 5), (3, 10), (50, 100), (99, 100), (7, 7), (400, 1000)])
def test_wilson_is_the_set_of_proportions_its_score_test_accepts(k, n):
    """Wilson's interval: every p with |k/n - p| <= z sqrt(p (1 - p) / n), found on a grid."""
    z = 1.959963984540054
    p = np.linspace(0, 1, 2_000_001)
    ok = np.abs(k / n - p) <= z * np.sqrt(p * (1 - p) / n)
    lo, hi = wilson(np.array([k]), np.array([n]))
    assert abs(lo[0] - p[ok].min()) < 1e-6 and abs(hi[0] - p[ok].max()) < 1e-6


def test_rows_count_every_target_once():
    rng = np.random.default_rng(0)
    scr = np.concatenate([rng.normal(8, 9, 300), [np.nan, np.inf, -np.inf]])
    found = rng.random(scr.size) < 0.6
    rows = {r["scr_bin"]: r for r in scr_rows({"measured": (scr, found)})}
    assert sum(r["targets"] for r in rows.values()) == scr.size
    sel = (scr >= 5) & (scr < 10)
    assert rows["5-10"]["targets"] == sel.sum()
    assert rows["5-10"]["detected"] == found[sel].sum()
    assert rows["5-10"]["scr_mean_db"] == pytest.approx(scr[sel].mean(), abs=1e-9)
    assert rows["n/a"]["targets"] == 1 and np.isnan(rows["n/a"]["scr_mean_db"])


def test_the_simulator_declares_each_targets_known_scr():
    """Known SCR = mean clean intensity over the target's pixels / its clutter mean; the
    measured SCR (speckled image, clutter ring) is close to it."""
    b = ts.simulate.chips(12, size=96, length_px=(16, 30), model="exponential", seed=4)
    measured = []
    for i in range(len(b)):
        t = b.meta[i]["targets"][0]
        body = b.instances[i, 0] == 1
        known = 10 * math.log10(float(b.clean[i, 0][body].double().mean()) / t["clutter_mean"])
        assert t["scr_db"] == pytest.approx(known, abs=1e-4)
        assert b.meta[i]["shadow"] == "ignore"
        ids = b.instances[i].numpy().astype(np.int64)
        box = np.array([b.meta[i]["boxes"][0]], dtype=float)
        measured.append(
            target_scr_db(b.image[i].numpy(), ids, b.ignore[i].numpy(), box, np.zeros(1, int))[0]
            - t["scr_db"]
        )
    assert np.median(np.abs(measured)) < 0.5


# -- Pd versus SCR of CA-CFAR against the textbook curve ---------------------------------------

SCR_LEVELS = (-2.5, 2.5, 7.5, 12.5, 17.5, 22.5)
GRID, SIZE = 16, 256


class PointTargets(torch.utils.data.Dataset):
    """Unit-mean exponential clutter (single-look speckle) with one-pixel targets every 16
    pixels; a target's clean intensity is SCR x the clutter mean and, as in the simulator
    (image = clean x unit-mean speckle), its pixel is speckled too: its intensity is
    exponential with mean SCR. The known SCRs cycle through :data:`SCR_LEVELS`."""

    def __init__(self, n: int) -> None:
        self.n = n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> dict:
        gen = torch.Generator().manual_seed(1000 + i)
        clean = torch.ones(SIZE, SIZE, dtype=torch.float64)
        inst = torch.zeros(SIZE, SIZE, dtype=torch.int32)
        scr = []
        for k, (r, c) in enumerate(
            (r, c) for r in range(8, SIZE, GRID) for c in range(8, SIZE, GRID)
        ):
            scr.append(SCR_LEVELS[(k + i) % len(SCR_LEVELS)])
            clean[r, c] = 10 ** (scr[-1] / 10)
            inst[r, c] = k + 1
        speckle = torch.empty(SIZE, SIZE, dtype=torch.float64).exponential_(1.0, generator=gen)
        return {
            "image": (clean * speckle).float()[None],
            "mask": inst[None] > 0,
            "instances": inst[None],
            "ignore": torch.zeros(1, SIZE, SIZE, dtype=torch.bool),
            "meta": {"name": f"points/{i}", "scr_db": scr},
        }


def _textbook_pd(scr_db: float, n: int, alpha: float) -> float:
    """CA-CFAR on exponential clutter: the test ``I > alpha * mean of N ring cells``; the ring
    sum is Gamma(N, 1), and for a target intensity exponential with mean S,
    ``Pd = E[exp(-alpha X / (N S))] = (1 + alpha / (N S))^-N`` (S = 1: Pfa)."""
    s = 10 ** (scr_db / 10)
    return (1 + alpha / (n * s)) ** -n


def test_textbook_formula_agrees_with_monte_carlo():
    """The reference curve itself, by brute force over independent cells (fixed seed)."""
    n, pfa = 144, 1e-3
    alpha = n * (pfa ** (-1 / n) - 1)
    rng = np.random.default_rng(0)
    trials = 400_000
    ring = rng.gamma(n, 1.0, trials) / n
    for scr_db in (0.0, *SCR_LEVELS[1:]):
        target = 10 ** (scr_db / 10) * rng.exponential(size=trials)
        mc = float(np.mean(target > alpha * ring))
        ref = _textbook_pd(scr_db, n, alpha)
        assert abs(mc - ref) < 4 * math.sqrt(ref * (1 - ref) / trials) + 1e-5, scr_db


def test_ca_cfar_pd_versus_scr_follows_the_textbook_curve():
    """Pd per known-SCR bin of ``ca`` (guard 2, train 4, pfa 1e-3: N = 13^2 - 5^2 = 144
    cells; every object of >= 1 px kept) against the textbook curve: each bin's interval
    holds it (1024 targets per bin; checked at the table's 95 % and, as a family of six
    bins, at 99.9 %); the curve 1.5 dB off falls outside where Pd is steep."""
    g, t, pfa = 2, 4, 1e-3
    n = (2 * (g + t) + 1) ** 2 - (2 * g + 1) ** 2
    alpha = n * (pfa ** (-1 / n) - 1)  # Pfa = (1 + alpha / N)^-N
    scoring = te.Scoring(
        rules=ObjectRules(closing=0, min_area=1), matching=Matching("centroid"), replicates=0
    )
    res = te.evaluate({"points": PointTargets(24)}, ["ca"], scoring=scoring, progress=False)
    known = res.scr[res.scr.source == "known"].set_index("scr_bin")
    r = res.states["points"][0]
    strict = pd.DataFrame(r.objects.scr_rows(r.threshold, level=0.999))
    strict = strict[strict.source == "known"].set_index("scr_bin")
    assert list(known.index) == ["<0", "0-5", "5-10", "10-15", "15-20", ">=20"]
    assert (known.targets == 1024).all()
    for name, level in zip(known.index, SCR_LEVELS, strict=True):
        row = known.loc[name]
        assert row.scr_mean_db == pytest.approx(level)
        ref = _textbook_pd(level, n, alpha)
        assert strict.loc[name, "pd_lo"] <= ref <= strict.loc[name, "pd_hi"], (name, row.pd, ref)
        assert row.pd_lo <= ref <= row.pd_hi, (name, row.pd, ref)
    for name, level in (("5-10", 7.5), ("10-15", 12.5)):
        for off in (-1.5, 1.5):
            ref = _textbook_pd(level + off, n, alpha)
            assert not strict.loc[name, "pd_lo"] <= ref <= strict.loc[name, "pd_hi"]


@pytest.mark.parametrize("n", [1, 2, 3, 5, 7, 11, 36, 1000])
def test_wilson_bounds_are_exact_at_none_and_all(n):
    """At k = 0 the lower bound is exactly 0 and at k = n the upper is exactly 1 (rounding
    once left 5.6e-17 at 0 / 3, which broke the Pd-vs-SCR error bars)."""
    lo, hi = wilson(np.array([0, n]), np.array([n, n]))
    assert lo[0] == 0.0 and hi[1] == 1.0
    assert 0 < hi[0] < 1 and 0 < lo[1] < 1
    k = np.arange(n + 1)
    lo, hi = wilson(k, np.full(n + 1, n))
    assert (lo <= k / n).all() and (hi >= k / n).all()
