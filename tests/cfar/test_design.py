"""Design thresholds without an image equal the thresholds the detectors report."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import torchsar as ts
from torchsar.cfar.design import THRESHOLDS
from torchsar.errors import OptionError

EXTRA = {
    "ca": {"looks": st.sampled_from([0.5, 1.0, 3.0])},
    "gamma": {"looks": st.sampled_from([0.5, 1.0, 3.0])},
    "os": {"rank": st.one_of(st.none(), st.integers(1, 40))},
    "two_parameter": {"k": st.one_of(st.none(), st.floats(0, 10))},
    "ac": {"censor_pfa": st.sampled_from([None, 1e-2])},
}
CHEAP = sorted(n for n in (fn.__name__ for fn in THRESHOLDS) if n not in ("k", "g0"))


@pytest.mark.parametrize("name", CHEAP)
@settings(max_examples=6, deadline=None)
@given(data=st.data())
def test_threshold_equals_the_detectors(name, data):
    opts = {
        "guard": data.draw(st.integers(0, 2)),
        "train": data.draw(st.integers(1, 3)),
        "pfa": data.draw(st.sampled_from([1e-2, 1e-3, 1e-4])),
    }
    opts |= {key: data.draw(s) for key, s in EXTRA.get(name, {}).items()}
    fn = getattr(ts.cfar, name)
    x = torch.empty(1, 1, 16, 16).exponential_(generator=torch.Generator().manual_seed(0))
    reported = fn(x, **opts).threshold  # in the statistic's dtype
    assert torch.tensor(ts.cfar.threshold(name, **opts), dtype=reported.dtype) == reported
    assert ts.cfar.threshold(fn, **opts) == ts.cfar.threshold(name, **opts)


def test_every_detector_is_registered():
    # os_mask is os's mask alone, not a detector of its own
    helpers = ("Detection", "detection_from", "threshold", "os_mask")
    exported = {n for n in ts.cfar.__all__ if n not in helpers}
    assert exported == {fn.__name__ for fn in THRESHOLDS}


def test_defaults_come_from_the_detector():
    x = torch.empty(1, 1, 20, 20).exponential_(generator=torch.Generator().manual_seed(1))
    for name in ("k", "g0", "go"):
        reported = getattr(ts.cfar, name)(x).threshold
        assert torch.tensor(ts.cfar.threshold(name), dtype=reported.dtype) == reported


@pytest.mark.parametrize(
    ("detector", "options", "match"),
    [
        ("ca", {"bogus": 1}, "ca has no option bogus; options: guard, train, pfa, looks"),
        ("nope", {}, "detector must be one of ac, ca"),
        (len, {}, "detector must be one of"),
        ("os", {"rank": 0}, "rank must be >= 1"),
        ("ca", {"pfa": 2.0}, "pfa must be a probability"),
        ("go", {"train": 0}, "train must be >= 1"),
        ("vi", {"k_mr": 0}, "k_mr must be finite and > 0"),
        ("ac", {"iterations": -1}, "iterations must be >= 0"),
        ("ac", {"censor_pfa": 1.5}, "censor_pfa must be a probability"),
        ("g0", {"looks": -1.0}, "looks must be finite and > 0"),
    ],
)
def test_bad_options(detector, options, match):
    with pytest.raises(OptionError, match=match):
        ts.cfar.threshold(detector, **options)
