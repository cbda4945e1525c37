"""``pfa --dataset``: measured false-alarm rate on a dataset's clutter pixels."""

from __future__ import annotations

import numpy as np
import pandas as pd
from skimage import io

from torchsar_eval.cli import main


def test_pfa_on_a_dataset_counts_only_clutter_pixels(tmp_path):
    rng = np.random.default_rng(0)
    root = tmp_path / "data"
    root.mkdir()
    for k in range(2):
        img = np.clip(rng.exponential(40, (40, 40)), 0, 255).astype(np.uint8)
        lab = np.zeros((40, 40), np.uint8)
        lab[5:10, 5:10] = 1  # 25 target pixels
        lab[30:34, 30:34] = 2  # 16 ignored pixels
        io.imsave(root / f"c{k}.png", img, check_contrast=False)
        io.imsave(root / f"c{k}.mask.png", lab, check_contrast=False)
    out = tmp_path / "out"
    argv = [
        "pfa",
        "--dataset",
        f"folder:{root}?type=amplitude",
        "--detectors",
        "ca,go",
        "--pfa",
        "0.01,0.001",
        "--out",
        str(out),
        "--no-progress",
    ]
    assert main(argv) == 0
    t = pd.read_csv(out / "pfa.csv")
    assert len(t) == 4 and set(t.detector) == {"ca", "go"}
    assert (t.pixels == 2 * (1600 - 25 - 16)).all()
    # the CSV's decimal text may differ from the quotient in its last bit
    assert np.allclose(t.measured_pfa, t.false_alarms / t.pixels, rtol=1e-12, atol=0)
    assert (t.ci_low <= t.measured_pfa).all() and (t.measured_pfa <= t.ci_high).all()
    for det, g in t.groupby("detector"):  # a lower design Pfa never detects more
        g = g.sort_values("design_pfa")
        assert g.false_alarms.is_monotonic_increasing, det
