"""The scene detection table and the seam merger's records: against direct per-component
computations on whole masks, hand-computed georeferencing, and the evaluator's reader."""

from __future__ import annotations

import json
import random

import numpy as np
import pandas as pd
import pytest
from scipy import ndimage

from torchsar.errors import OptionError
from torchsar.io.georef import AffineGeoref
from torchsar.tiling import SeamMerger, plan_tiles
from torchsar.tiling.table import DETECTION_COLUMNS, detection_table, write_csv, write_geojson


def _reference(mask: np.ndarray, score: np.ndarray) -> pd.DataFrame:
    """Each 8-connected component of the whole mask, computed pixel by pixel."""
    lab, n = ndimage.label(mask, structure=np.ones((3, 3), bool))
    rows = []
    for k in range(1, n + 1):
        rr, cc = np.nonzero(lab == k)
        s = score[rr, cc]
        best = max(range(rr.size), key=lambda i: (s[i], -rr[i], -cc[i]))
        rows.append(
            {
                "row": rr.mean(),
                "col": cc.mean(),
                "peak_row": rr[best],
                "peak_col": cc[best],
                "score": s[best],
                "area": rr.size,
                "row_min": rr.min(),
                "row_max": rr.max(),
                "col_min": cc.min(),
                "col_max": cc.max(),
            }
        )
    df = pd.DataFrame(rows)
    return df.sort_values(
        ["score", "peak_row", "peak_col"], ascending=[False, True, True], kind="mergesort"
    ).reset_index(drop=True)


def _scene(seed: int, shape=(47, 61)) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    mask = ndimage.binary_dilation(rng.random(shape) < 0.03, iterations=int(rng.integers(0, 3)))
    score = np.round(rng.random(shape) * 8) / 2  # ties on purpose
    return mask, score


@pytest.mark.parametrize("seed", range(6))
def test_records_merged_in_any_order_equal_whole_mask_components(seed):
    """Records summarised per tile (a separate merger each, as in worker processes),
    saved as plain arrays and merged in a shuffled order, give the components of the whole
    mask; merging in raster order gives the same bytes as add()."""
    mask, score = _scene(seed)
    tile = [(7, 9), (16, 16), (13, 30)][seed % 3]
    tiles = plan_tiles(mask.shape, tile, 0)
    records = [SeamMerger(mask.shape).summarise(t, mask[t.core], score[t.core]) for t in tiles]
    for r in records:  # only arrays and ints: what a data-only state file holds
        assert all(isinstance(v, np.ndarray | int | tuple) for v in r.values())
    shuffled = SeamMerger(mask.shape)
    for r in random.Random(seed).sample(records, len(records)):
        shuffled.merge(r)
    ref = _reference(mask, score)
    got = shuffled.table()
    pd.testing.assert_frame_equal(got, ref[got.columns], check_dtype=False)
    ordered, added = SeamMerger(mask.shape), SeamMerger(mask.shape)
    for t, r in zip(tiles, records, strict=True):
        ordered.merge(r)
        added.add(t, mask[t.core], score[t.core])
    assert ordered.table().to_csv() == added.table().to_csv()


def test_record_of_an_empty_tile():
    m = SeamMerger((10, 10))
    t = plan_tiles((10, 10), 5, 0)[0]
    rec = m.summarise(t, np.zeros((5, 5), bool), np.zeros((5, 5)))
    assert rec["n"] == 0 and all(e.sum() == 0 for e in rec["edges"])
    m.merge(rec)
    assert len(m.table()) == 0


def _objects() -> pd.DataFrame:
    mask = np.zeros((40, 50), bool)
    mask[5:8, 10:20] = True  # 3 x 10 box
    mask[30, 40] = True
    score = np.zeros(mask.shape)
    score[6, 15] = 9.0
    score[5:8, 10:20] += 1.0
    score[30, 40] = 4.0
    return _reference(mask, score)


def test_columns_peak_centroid_and_length():
    t = detection_table(_objects(), "scene-a", pixel_spacing=(10.0, 2.5))
    assert tuple(t.columns) == DETECTION_COLUMNS
    first = t.iloc[0]
    assert (first.detect_scene_row, first.detect_scene_column) == (6, 15)  # the peak
    assert (first.centroid_row, first.centroid_col) == (6.0, 14.5)
    assert first.area_px == 30 and first.score == 10.0
    assert first.length_m == max(3 * 10.0, 10 * 2.5)  # larger box side in metres
    assert t.iloc[1].length_m == 10.0
    assert t["scene_id"].tolist() == ["scene-a", "scene-a"]
    assert t["lat"].isna().all() and t["lon"].isna().all()
    none = detection_table(_objects(), "s")
    assert none["length_m"].isna().all()


def test_lonlat_from_an_affine_georef_by_hand():
    g = AffineGeoref((0.001, 0.0, 10.0, 0.0, -0.002, 50.0), epsg=4326, geographic=True)
    t = detection_table(_objects(), "s", georef=g)
    # PixelIsArea: pixel (r, c) is raster coordinate (r + 0.5, c + 0.5)
    assert t.loc[0, "lon"] == pytest.approx(10.0 + 0.001 * 15.5)
    assert t.loc[0, "lat"] == pytest.approx(50.0 - 0.002 * 6.5)
    assert t.loc[1, "lon"] == pytest.approx(10.0 + 0.001 * 40.5)


def test_csv_is_read_back_by_the_evaluator(tmp_path):
    from torchsar_eval.saved.table import read_points

    t = detection_table(_objects(), "scene-a", pixel_spacing=(10.0, 2.5))
    path = write_csv(t, tmp_path / "d.csv")
    back = read_points(path)
    assert back.refs.tolist() == ["scene-a", "scene-a"]
    np.testing.assert_array_equal(back.point, t[["detect_scene_row", "detect_scene_column"]])
    np.testing.assert_array_equal(back.score, t["score"])
    np.testing.assert_array_equal(back.length_m, t["length_m"])
    again = pd.read_csv(path)
    pd.testing.assert_frame_equal(again, t, check_dtype=False)
    assert write_csv(t, tmp_path / "e.csv").read_bytes() == path.read_bytes()


def test_geojson_points_and_properties(tmp_path):
    g = AffineGeoref((0.001, 0.0, 10.0, 0.0, -0.002, 50.0), epsg=4326, geographic=True)
    t = detection_table(_objects(), "s", georef=g)  # no spacing: length_m unknown
    doc = json.loads(write_geojson(t, tmp_path / "d.geojson").read_text())
    assert doc["type"] == "FeatureCollection" and len(doc["features"]) == 2
    for f, (_, row) in zip(doc["features"], t.iterrows(), strict=True):
        assert f["geometry"] == {"type": "Point", "coordinates": [row.lon, row.lat]}
        assert f["properties"]["detect_scene_row"] == row.detect_scene_row
        assert f["properties"]["length_m"] is None
        assert list(f["properties"]) == list(DETECTION_COLUMNS)


def test_bad_inputs():
    with pytest.raises(OptionError, match="no georeferencing"):
        write_geojson(detection_table(_objects(), "s"), "unused.geojson")
    with pytest.raises(OptionError, match="pixel_spacing"):
        detection_table(_objects(), "s", pixel_spacing=(0, 1))
    with pytest.raises(OptionError, match="pixel_spacing"):
        detection_table(_objects(), "s", pixel_spacing="ten")
    with pytest.raises(OptionError, match="scene_id"):
        detection_table(_objects(), "")
    with pytest.raises(OptionError, match="lacks column"):
        detection_table(_objects().drop(columns="peak_row"), "s")
    empty = detection_table(_objects().iloc[:0], "s")
    assert len(empty) == 0 and tuple(empty.columns) == DETECTION_COLUMNS
