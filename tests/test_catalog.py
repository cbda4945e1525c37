"""One place per built-in detector: every registry is the modules' declarations."""

from __future__ import annotations

import importlib

import torchsar.cfar as cfar
from torchsar.catalog import builtin_specs
from torchsar.cfar.design import THRESHOLDS
from torchsar.detection import DetectorSpec
from torchsar_eval import choices
from torchsar_eval.colours import PALETTE, detector_colour
from torchsar_eval.registry import BUILTIN


def test_every_registry_is_read_from_the_declarations():
    specs = builtin_specs()
    names = [s.name for s in specs]
    assert [s.order for s in specs] == list(range(len(specs)))  # distinct, in order
    assert list(BUILTIN) == names == list(choices.BUILTIN_DETECTORS)
    for s in specs:
        det = BUILTIN[s.name]
        assert det.fn is s.detect and dict(det.options) == dict(s.options)
        assert detector_colour(s.name) == PALETTE[s.order]
        assert choices.BUILTIN_ORDER[s.name] == s.order
    assert {s.detect: s.threshold for s in specs if s.threshold is not None} == THRESHOLDS


def test_each_cfar_is_declared_in_its_own_module_and_exported():
    for s in builtin_specs():
        module = importlib.import_module(s.detect.__module__)
        assert module.SPEC is s and isinstance(s, DetectorSpec)
        if s.threshold is not None:  # a CFAR: exported by torchsar.cfar under its name
            assert getattr(cfar, s.detect.__name__) is s.detect
            assert s.detect.__name__ in cfar.__all__
            assert cfar.threshold(s.name, **s.options) > 0
