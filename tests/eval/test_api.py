"""The Python API: ``torchsar_eval.evaluate`` with detectors as objects, names and saved
predictions; tables equal to the command line's; errors that name the Python parameter."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

import torchsar as ts
import torchsar_eval as te
from torchsar.objects import Objects
from torchsar_eval.cli import main
from torchsar_eval.errors import EvalError


class Peaks(torch.nn.Module):
    """A module returning boxes of 3 x 3 around every local maximum above ``level`` x the
    image mean, scored by contrast through a sigmoid (probabilities)."""

    def __init__(self, level: float = 8.0) -> None:
        super().__init__()
        self.level = level

    def forward(self, x: torch.Tensor) -> Objects:
        b, c, h, w = x.shape
        flat = x.reshape(b * c, 1, h, w)
        peak = torch.nn.functional.max_pool2d(flat, 3, stride=1, padding=1) == flat
        ratio = flat / flat.mean(dim=(2, 3), keepdim=True)
        keep = peak & (ratio > self.level)
        p, _, r, col = torch.nonzero(keep, as_tuple=True)
        boxes = torch.stack([r - 1, col - 1, r + 2, col + 2], dim=1).double().numpy()
        score = torch.sigmoid(ratio[keep] - 2 * self.level).double().numpy()
        return Objects.from_boxes(boxes, score, plane=p.numpy(), planes=b * c, shape=(h, w))


def test_cli_and_api_give_the_same_tables(tmp_path):
    out = tmp_path / "cli"
    assert (
        main(
            [
                "run",
                "--dataset",
                "sim-chips",
                "--n",
                "6",
                "--detectors",
                "ca,region",
                "--no-progress",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    res = te.evaluate("sim-chips", ["ca", "region"], n=6, progress=False)
    pd.testing.assert_frame_equal(res.summary, pd.read_csv(out / "summary.csv"), check_dtype=False)
    pd.testing.assert_frame_equal(
        res.per_image, pd.read_csv(out / "per_image.csv"), check_dtype=False
    )
    assert res.out is None and res.files == []


def test_objects_detectors_dicts_and_datasets_as_objects(tmp_path):
    from torchsar_eval.datasets import make_dataset

    chips = make_dataset("sim-chips", n=6)
    res = te.evaluate(
        {"chips": chips},
        {"peaks": Peaks(level=6.0), "os": "os", "mine": lambda x: ts.cfar.go(x, pfa=1e-2)},
        scoring=te.Scoring(replicates=0),
        progress=False,
    )
    s = res.summary.set_index("detector")
    assert list(s.index) == ["peaks", "os", "mine"] and (s.images == 6).all()
    assert s.loc["peaks", "tp"] > 0 and pd.isna(s.loc["peaks", "pd_pixel"])
    # no threshold declared: every object of the box detector counts at the operating point
    assert s.loc["peaks", "score_threshold"] == -np.inf
    assert res.states["chips"][0].objects.design_threshold is None


def test_declared_threshold_sets_the_operating_point():
    det = te.Detector("peaks", Peaks(level=6.0), threshold=0.9)
    loose = te.evaluate(
        "sim-chips", [te.Detector("peaks", Peaks(level=6.0))], n=6, progress=False
    ).summary.iloc[0]
    strict = te.evaluate("sim-chips", [det], n=6, progress=False).summary.iloc[0]
    assert strict.score_threshold == pytest.approx(0.9)
    assert strict.tp + strict.fp <= loose.tp + loose.fp
    assert strict.ap50 == loose.ap50  # AP ranks every object whatever the threshold


def test_out_is_written_and_overwritten_when_asked(tmp_path):
    out = tmp_path / "run"
    first = te.evaluate("sim-chips", ["ca"], n=2, out=out, progress=False)
    assert first.out == out and (out / "summary.csv").is_file() and "config.json" in first.files
    with pytest.raises(EvalError, match=r"out=.* holds a previous run: pass overwrite=True"):
        te.evaluate("sim-chips", ["ca"], n=2, out=out, progress=False)
    te.evaluate("sim-chips", ["so"], n=2, out=out, overwrite=True, progress=False)
    assert pd.read_csv(out / "summary.csv").detector.tolist() == ["so"]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"detectors": []}, "detectors= is empty"),
        ({"detectors": ["ca", "ca"]}, "detectors= names ca more than once"),
        ({"detectors": [42]}, "a detector must be callable"),
        ({"detectors": ["nope"]}, "unknown detector 'nope'"),
        ({"resume": True}, "resume=True needs out=FOLDER"),
        ({"export_coco": True}, "export_coco=True needs out=FOLDER"),
        ({"window_units": "km"}, "window_units='km'"),
        ({"execution": "fast"}, "execution='fast': expected a torchsar_eval.Execution"),
        ({"scoring": {"iou": 0.5}}, "expected a torchsar_eval.Scoring"),
    ],
)
def test_errors_name_the_python_parameter(kwargs, message):
    kwargs = {"detectors": ["ca"], **kwargs}
    with pytest.raises(EvalError, match=message):
        te.evaluate("sim-chips", n=2, progress=False, **kwargs)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: te.Execution(workers=0), "workers=0: must be an integer >= 1"),
        (lambda: te.Execution(engine="spark"), "engine='spark'"),
        (
            lambda: (
                te.Execution(device="cuda:7")
                if not torch.cuda.is_available()
                else te.Execution(device="nope")
            ),
            "device=",
        ),
        (lambda: te.Calibration("recall=1"), "calibration target must be"),
        (lambda: te.Scoring(instances="some"), "instances='some'"),
    ],
)
def test_settings_are_checked_when_built(make, message):
    with pytest.raises(EvalError, match=message):
        make()


def test_cli_renders_the_same_errors_as_flags(tmp_path, capsys):
    out = tmp_path / "run"
    assert (
        main(
            [
                "run",
                "--dataset",
                "sim-chips",
                "--n",
                "2",
                "--detectors",
                "ca",
                "--no-progress",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "run",
                "--dataset",
                "sim-chips",
                "--n",
                "2",
                "--detectors",
                "ca",
                "--no-progress",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "error: --out " in err and "pass --overwrite to replace it" in err


def test_wrong_outputs_are_named():
    with pytest.raises(EvalError, match="returned ndarray: a detector must return"):
        te.evaluate("sim-chips", {"bad": lambda x: np.zeros(3)}, n=2, progress=False)
    with pytest.raises(EvalError, match="returned Objects of 1 planes"):
        te.evaluate(
            "sim-chips",
            {"bad": lambda x: Objects.empty(1, (9, 9))},
            n=2,
            execution=te.Execution(batch_size=2, progress=False),
        )


def test_results_do_not_depend_on_batch_or_shard_size():
    a = te.evaluate(
        "sim-chips",
        {"peaks": Peaks(6.0), "region": "region"},
        n=7,
        execution=te.Execution(batch_size=3, shard_size=2, progress=False),
    )
    b = te.evaluate(
        "sim-chips",
        {"peaks": Peaks(6.0), "region": "region"},
        n=7,
        execution=te.Execution(batch_size=16, shard_size=256, progress=False),
    )
    pd.testing.assert_frame_equal(a.summary, b.summary)
    pd.testing.assert_frame_equal(a.froc, b.froc)
    pd.testing.assert_frame_equal(a.pr, b.pr)


def test_region_cfar_is_scored_by_its_regions_unless_discrimination_is_asked():
    """Own instances: one object per region of the region CFAR (its labels); with
    ``instances="discriminate"`` its statistic goes through the closing and size rules."""
    from torchsar_eval.datasets import make_dataset

    chips = make_dataset("sim-chips", n=4)
    own = te.evaluate(
        {"c": chips}, ["region"], progress=False, scoring=te.Scoring(replicates=0)
    ).states["c"][0]
    forced = te.evaluate(
        {"c": chips},
        ["region"],
        progress=False,
        scoring=te.Scoring(replicates=0, instances="discriminate"),
    )
    x = torch.stack([chips[i]["image"] for i in range(4)])
    d = ts.region.region_cfar(x)
    regions = sum(int(np.unique(d.labels[i].numpy()).size) - 1 for i in range(4))
    assert own.objects.detections == regions  # every region, as it is
    rules = te.Scoring().rules
    objs = ts.objects.discriminate(d.statistic, d.threshold, rules=rules)
    assert forced.states["c"][0].objects.detections == len(objs)


def test_idle_workers_are_named_in_one_line():
    import warnings

    from torchsar_eval.api import _note_idle_workers
    from torchsar_eval.settings import Execution

    with pytest.warns(
        UserWarning,
        match=r"100 images make 1 shard\(s\) of at most 256, so only "
        r"1 of the 2 workers have work",
    ):
        _note_idle_workers("d", 100, Execution(workers=2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _note_idle_workers("d", 600, Execution(workers=2))  # 3 shards: both busy
        _note_idle_workers("d", 100, Execution(workers=1))


def test_a_run_leaves_the_callers_garbage_collector_as_it_was():
    """The run's collections skip the caller's heap (frozen for the run), and the heap is
    thawed after; a caller that froze objects itself keeps them frozen."""
    import gc

    assert gc.get_freeze_count() == 0
    te.evaluate("sim-chips", ["ca"], n=2, scoring=te.Scoring(replicates=0), progress=False)
    assert gc.get_freeze_count() == 0 and gc.isenabled()
    gc.freeze()
    try:
        frozen = gc.get_freeze_count()
        te.evaluate("sim-chips", ["ca"], n=2, scoring=te.Scoring(replicates=0), progress=False)
        assert gc.get_freeze_count() > frozen // 2  # not thawed (a few freed meanwhile)
    finally:
        gc.unfreeze()
