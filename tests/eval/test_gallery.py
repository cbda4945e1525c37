"""The gallery of worst cases: bounded, the global top cases whatever the sharding or the
batch size, crops showing the case, written as the PNGs ``gallery/cases.csv`` names."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch
from PIL import Image

import torchsar as ts
import torchsar_eval as te
from torchsar.metrics import match_batch
from torchsar_eval import statefile
from torchsar_eval.commands.run import DEFAULT_MATCH, DEFAULT_RULES
from torchsar_eval.gallery import (
    CROP,
    FOCUS,
    FOUND,
    GALLERY_CASES,
    HITS,
    TRUTH,
    Cases,
    Gallery,
    render_case,
    write_gallery,
)
from torchsar_eval.registry import BUILTIN
from torchsar_eval.result import Scoring
from torchsar_eval.runner import run_detectors
from torchsar_eval.scoring import batch_truth
from torchsar_eval.shards import ShardJob, run_shards

DETECTORS = ["ca", "so", "lognormal"]  # few false alarms, many, and none at all (all missed)
N = 16


class Chips(torch.utils.data.Dataset):
    """Simulated 64 x 64 chips, one target each, generated on demand."""

    def __init__(self, n: int) -> None:
        self.n = n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> dict:
        item = ts.simulate.chips(1, size=64, length_px=(12, 24), seed=5, start=i)[0]
        item["meta"] = {"name": f"chip{i}", "index": i, **item["meta"]}
        return item


SCORING = Scoring(DEFAULT_RULES, DEFAULT_MATCH, replicates=0)


def _galleries(tmp_path, shard_size: int, batch_size: int) -> dict[str, Gallery]:
    job = ShardJob(
        "chips",
        Chips(N),
        list(range(N)),
        [BUILTIN[d] for d in DETECTORS],
        SCORING,
        te.Execution(batch_size=batch_size, shard_size=shard_size, progress=False),
    )
    merged, _ = run_shards(job, tmp_path / f"s{shard_size}-b{batch_size}")
    return {r.detector.name: r.gallery for r in merged}


def _same(a: Cases, b: Cases) -> None:
    assert a.keys == b.keys and a.info == b.info
    assert np.array_equal(a.image, b.image, equal_nan=True)
    assert np.array_equal(a.masks, b.masks)


@pytest.fixture(scope="module")
def reference():
    """Every false alarm and miss at the operating point, straight from the matching (one
    batch of all images): ``{detector: (fa [(score, image)], misses [(area, image)])}``."""
    found: dict[str, tuple[list, list]] = {d: ([], []) for d in DETECTORS}

    def collect(batch, objects):
        gt, info = batch_truth(batch, "chips")
        for name, obj in objects.items():
            m = match_batch(obj, gt, DEFAULT_MATCH)
            counted = obj.score > obj.threshold  # the design threshold
            hit = set(m.op[counted & (m.op >= 0)].tolist())
            found[name][0].extend(
                (float(s), info[p].key)
                for s, p in zip(
                    obj.score[counted & (m.op == -1)],
                    obj.plane[counted & (m.op == -1)],
                    strict=True,
                )
            )
            found[name][1].extend(
                (int(gt.area[g]), info[gt.plane[g]].key) for g in range(len(gt)) if g not in hit
            )

    results = run_detectors(
        Chips(N),
        [BUILTIN[d] for d in DETECTORS],
        batch_size=N,
        scoring=SCORING,
        progress=False,
        on_batch=collect,
    )
    rows = {r.detector.name: r.rows for r in results}
    for d in DETECTORS:  # the reference agrees with the per-image counts
        assert len(found[d][0]) == sum(row[3] for row in rows[d])
        assert len(found[d][1]) == sum(row[4] for row in rows[d])
    return found, {r.detector.name: r.gallery for r in results}


def test_the_gallery_holds_the_global_top_cases(reference):
    found, galleries = reference
    assert len(found["so"][0]) > GALLERY_CASES and len(found["lognormal"][1]) > GALLERY_CASES
    for d in DETECTORS:
        fa, miss = galleries[d].false_alarms, galleries[d].misses
        assert len(fa) == min(GALLERY_CASES, len(found[d][0]))
        assert len(miss) == min(GALLERY_CASES, len(found[d][1]))
        top = sorted((s for s, _ in found[d][0]), reverse=True)[:GALLERY_CASES]
        assert [i["score"] for i in fa.info] == pytest.approx(top)
        largest = sorted((a for a, _ in found[d][1]), reverse=True)[:GALLERY_CASES]
        assert [i["area"] for i in miss.info] == largest
        assert {(i["score"], i["image"]) for i in fa.info} <= set(found[d][0])
        assert {(i["area"], i["image"]) for i in miss.info} <= set(found[d][1])


@pytest.mark.parametrize(("shard_size", "batch_size"), [(1, 1), (5, 2), (4, 3)])
def test_any_shard_or_batch_size_gives_the_same_gallery(
    tmp_path, reference, shard_size, batch_size
):
    whole = reference[1]
    parts = _galleries(tmp_path, shard_size, batch_size)
    for d in DETECTORS:
        _same(whole[d].false_alarms, parts[d].false_alarms)
        _same(whole[d].misses, parts[d].misses)
        _same(whole[d].hits, parts[d].hits)
        assert whole[d].shapes == parts[d].shapes == [(64, 64)]


def test_merging_is_associative_and_keeps_the_best():
    def cases(values: list[float], image: str) -> Cases:
        n = len(values)
        return Cases(
            "false_alarm",
            3,
            [(-v, 0, image, 0.0, 0.0) for v in values],
            [{"score": v, "image": image} for v in values],
            np.full((n, CROP, CROP), 1, np.float16),
            np.zeros((n, CROP, CROP), np.uint8),
        )

    a, b, c = cases([5, 1], "a"), cases([4, 3, 2], "b"), cases([5, 0.5], "c")
    left, right = (a + b) + c, a + (b + c)
    _same(left, right)
    # a tie in score (5 in a and in c) is broken by the image name, the same either way
    assert [(i["score"], i["image"]) for i in left.info] == [(5, "a"), (5, "c"), (4, "b")]


def test_a_crop_shows_its_case_from_the_image(reference):
    galleries = reference[1]
    chips = Chips(N)
    for d in ("ca", "lognormal"):
        g = galleries[d]
        for kind, cases, own in (("fa", g.false_alarms, FOUND), ("miss", g.misses, TRUTH)):
            for info, image, masks in zip(cases.info, cases.image, cases.masks, strict=True):
                focus = (masks & FOCUS) > 0
                assert focus.any(), (d, kind)
                assert ((masks & own) > 0)[focus].all()  # the case is a detection / a target
                # the crop's samples are the image's (dB), centred on the case (objects here
                # are smaller than a crop: one sample per pixel)
                item = chips[int(info["image"].removeprefix("chip"))]
                x = item["image"][0].numpy().astype(np.float64)
                rr, cc = int(np.floor(info["row"] + 0.5)), int(np.floor(info["col"] + 0.5))
                if 0 <= rr < 64 and 0 <= cc < 64:
                    want = 10 * np.log10(x[rr, cc])
                    assert float(image[CROP // 2, CROP // 2]) == pytest.approx(want, abs=0.05)


def test_written_gallery_matches_its_index(tmp_path, reference):
    galleries = reference[1]

    class R:  # what write_gallery reads of a result
        def __init__(self, name: str) -> None:
            self.detector = type("D", (), {"name": name})()
            self.gallery = galleries[name]

    files = write_gallery(tmp_path, {"chips": [R(d) for d in DETECTORS]}, {"chips": "chips"})
    assert files == ["gallery/"]
    index = pd.read_csv(tmp_path / "gallery" / "cases.csv")
    for d in DETECTORS:
        rows = index[index.detector == d]
        g = galleries[d]
        assert (rows.kind == "false_alarm").sum() == len(g.false_alarms)
        assert (rows.kind == "miss").sum() == len(g.misses)
        assert (rows.kind == "hit").sum() == len(g.hits)
        assert rows[rows.kind == "hit"].why.str.startswith("matched").all()
    for f in index.file:
        with Image.open(tmp_path / f) as im:
            assert im.format == "PNG" and im.size == (2 * CROP, 2 * CROP)
            rgb = np.asarray(im.convert("RGB"))
        assert rgb.std() > 0  # not blank
    magenta = np.array([255, 64, 255])
    first_fa = index[(index.detector == "so") & (index.kind == "false_alarm")].file.iloc[0]
    with Image.open(tmp_path / first_fa) as im:
        assert (np.asarray(im.convert("RGB")) == magenta).all(axis=-1).any()  # outlined


@pytest.mark.parametrize("defer_bytes", [0, 1 << 40])
def test_deferred_cases_are_the_cases_built_at_once(tmp_path, reference, monkeypatch, defer_bytes):
    """Cases built only when the gallery is saved (candidates pushed out meanwhile never
    built) equal those built as offered, batch after batch."""
    import torchsar_eval.gallery as gallery_module

    monkeypatch.setattr(gallery_module, "DEFER_BYTES", defer_bytes)
    results = run_detectors(
        Chips(N), [BUILTIN[d] for d in DETECTORS], batch_size=2, scoring=SCORING, progress=False
    )
    for r in results:
        whole = reference[1][r.detector.name]
        _same(whole.false_alarms, r.gallery.false_alarms)
        _same(whole.misses, r.gallery.misses)
        _same(whole.hits, r.gallery.hits)


def test_pending_cases_are_built_when_saved_or_merged():
    built = []

    def make(j):
        built.append(j)
        return {"j": j}, np.zeros((CROP, CROP), np.float16), np.zeros((CROP, CROP), np.uint8)

    a = Cases("false_alarm", 2)
    a.offer([(3.0,), (1.0,), (2.0,)], make, defer=True)
    a.offer([(0.5,)], make, defer=True)  # pushes (2.0,) out before it was ever built
    assert built == [] and len(a) == 2
    back = statefile.loads(statefile.dumps(a), "test")
    assert built == [1, 0] and back.keys == [(0.5,), (1.0,)]
    assert [i["j"] for i in back.info] == [0, 1]


def test_a_missed_target_under_a_detection_keeps_the_miss_colour():
    """The case's own ring is drawn last in its kind's colour: a missed target lying under a
    rejected detection is ringed green, a false alarm on a target magenta."""
    from torchsar_eval.gallery import _FOUND, _TRUTH, SCALE, _ring

    masks = np.zeros((CROP, CROP), np.uint8)
    masks[40:56, 40:56] |= TRUTH | FOCUS  # the missed target
    masks[36:60, 36:60] |= FOUND  # a larger detection over it that failed the rule
    image = np.zeros((CROP, CROP), np.float16)
    focus = np.kron((masks & FOCUS) > 0, np.ones((SCALE, SCALE), bool))
    ring = _ring(focus, 2)
    assert (render_case(image, masks, "miss")[ring] == _TRUTH).all()
    swapped = masks.copy()
    swapped[40:56, 40:56] = FOUND | FOCUS | TRUTH
    assert (render_case(image, swapped, "false_alarm")[ring] == _FOUND).all()


def test_crops_share_the_image_grey_scale():
    """With the image's stretch, one dB value is one grey in every crop of it."""
    a = np.full((CROP, CROP), 10.0)
    a[:8] = 0.0
    b = np.full((CROP, CROP), 10.0)
    b[:8] = 30.0
    masks = np.zeros((CROP, CROP), np.uint8)
    ga, gb = (render_case(x, masks, "miss", (0.0, 30.0)) for x in (a, b))
    assert ga[-1, -1] == gb[-1, -1]  # 10 dB in both
    assert render_case(a, masks, "miss")[-1, -1] != ga[-1, -1]  # the crop's own stretch differs


def test_hits_are_true_positives_drawn_at_random(reference):
    """Every hit is a detection matched at the operating point, ranked by a hash draw in
    [0, 1) (not by score), as many as there are up to the gallery's size."""
    _, galleries = reference
    assert any(len(g.hits) for g in galleries.values())
    for g in galleries.values():
        g.settle()
        assert len(g.hits) <= HITS
        assert all(i["why"].startswith("matched") for i in g.hits.info)
        draws = [k[0] for k in g.hits.keys]
        assert draws == sorted(draws) and all(0 <= v < 1 for v in draws)
