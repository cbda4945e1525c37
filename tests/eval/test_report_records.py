"""``config.json`` read as typed records: every field the pages use, from any document (an
older run, a newer one, a hand-edited file) without an error deep inside a page."""

from __future__ import annotations

import copy
import json

import pytest

import torchsar_eval as te
from torchsar_eval.html_report import build_report
from torchsar_eval.html_report.records import run_record


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "run"
    calibration = te.Calibration("f1", 0.5, sweep={"pfa": [1e-3, 1e-4]})
    te.evaluate("sim-chips", ["ca", "os"], n=6, out=out, calibration=calibration, progress=False)
    return out


def _paths(doc, prefix=()):
    """Every key path of a JSON document."""
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield (*prefix, k)
            yield from _paths(v, (*prefix, k))


def _replaced(doc, path, value):
    out = copy.deepcopy(doc)
    node = out
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return out


def test_the_record_holds_what_the_run_did(run):
    rec = run_record(json.loads((run / "config.json").read_text()))
    ds = rec.dataset("sim-chips")
    assert ds.generator and ds.image_sizes and ds.wall_s > 0 and ds.images_per_s > 0
    assert rec.calibration.target == "f1" and rec.calibration.sweep == {"pfa": [1e-3, 1e-4]}
    assert rec.matching.kind == "centroid" and rec.bootstrap.replicates > 0
    chosen = ds.chosen["ca"]["pfa"]
    assert rec.detector_options("sim-chips", "ca")["pfa"] == chosen in (1e-3, 1e-4)
    assert rec.dataset("no such dataset") == type(ds)()


@pytest.mark.parametrize("bad", [None, "text", 3, -1.5, [], {}, [1, "a"], True])
def test_any_field_of_any_type_gives_a_record(run, bad):
    doc = json.loads((run / "config.json").read_text())
    for path in _paths(doc):
        run_record(_replaced(doc, path, bad))  # never raises


@pytest.mark.figures
def test_a_page_is_built_from_a_config_with_wrong_types(run, tmp_path):
    doc = json.loads((run / "config.json").read_text())
    paths = [
        ("options", "throughput"),
        ("options", "scoring", "matching"),
        ("options", "calibration"),
        ("options", "datasets", "sim-chips"),
    ]
    for path in paths:
        for bad in ("text", [1], {"wall_s": "x", "kind": 3, "sweep": "x"}):
            (run / "config.json").write_text(json.dumps(_replaced(doc, path, bad)))
            try:
                assert "<html" in build_report([run])
            finally:
                (run / "config.json").write_text(json.dumps(doc))
