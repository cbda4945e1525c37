"""hrsid: and a COCO conversion of the same chips give the same tables end to end."""

from __future__ import annotations

import pandas as pd

from tests.eval.datasets_helpers import coco_from_id_maps, write_hrsid_folder
from torchsar.io import decode_id_map, read_raster
from torchsar_eval.cli import main
from torchsar_eval.datasets import make_dataset

TIMING = ("ms_", "time", "per_s", "seconds")  # columns that measure speed, not results


def test_hrsid_and_its_coco_conversion_give_the_same_summary(tmp_path, recwarn):
    root = write_hrsid_folder(tmp_path / "h")
    images = sorted(p for p in root.glob("P?.png"))
    ids = [
        decode_id_map(read_raster(root / f"{p.stem}_instance_id_RGB.png"), "x.png") for p in images
    ]
    coco = coco_from_id_maps(images, ids, tmp_path / "conv.json")
    specs = [f"hrsid:{root}", f"coco:{coco}?images={root}"]
    assert len(make_dataset(specs[1])) == 2
    tables = []
    for k, spec in enumerate(specs):
        out = tmp_path / f"out{k}"
        args = ["run", "--dataset", spec, "--detectors", "ca", "--out", str(out), "--no-progress"]
        assert main(args) == 0
        table = pd.read_csv(out / "summary.csv")
        timing = [c for c in table.columns if c == "dataset" or any(t in c for t in TIMING)]
        tables.append(table.drop(columns=timing))
    pd.testing.assert_frame_equal(tables[0], tables[1])
