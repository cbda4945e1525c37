"""The throughput report of ``scripts/benchmark.py`` on a tiny store: one row per worker
count whose figures agree with each other and with the run's own timing table."""

from __future__ import annotations

import pandas as pd
import pytest

from tests.scripts import SCRIPTS, load_script


@pytest.fixture(scope="module")
def bench():
    return load_script("benchmark")


def test_throughput_topic_reports_consistent_rows(bench, tmp_path, capsys):
    csv = tmp_path / "throughput.csv"
    assert (
        bench.main(
            [
                "--topic",
                "throughput",
                "--n",
                "3",
                "--workers",
                "1",
                "--device",
                "cpu",
                "--csv",
                str(csv),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "images/s" in printed and "scoring ms/chip/det" in printed
    rows = pd.read_csv(csv)
    assert len(rows) == 1
    r = rows.iloc[0]
    assert (r["workers"], r["images"]) == (1, 3)
    assert r["wall_s"] > 0
    assert r["images_per_s"] == pytest.approx(3 / r["wall_s"])
    assert r["detector_ms_per_image"] > 0 and r["scoring_ms_per_image"] > 0
    # eight detectors; one in-process worker: both parts lie within the wall time
    assert r["scoring_ms_per_chip_and_detector"] * 8 == pytest.approx(r["scoring_ms_per_image"])
    assert r["detector_ms_per_image"] + r["scoring_ms_per_image"] <= 1e3 * r["wall_s"] / 3


def test_report_topics_are_not_ab_cases(bench):
    mod = bench.load_topic(SCRIPTS / "benchmarks" / "throughput.py")
    assert hasattr(mod, "report") and not hasattr(mod, "cases")
    assert bench.load_cases(None, "throughput") == []
    assert mod.DETECTORS == ("ca", "two_parameter", "go", "so", "os", "vi", "ac", "region")
