"""Mutation fuzzing of the predictions readers (COCO results JSON, points CSV, mask
folders): a valid predictions file with a few fields changed (types swapped, NaN / inf /
huge / negative numbers, keys or columns removed, rows repeated, text cut short, nesting
deepened, arrays of another dtype, shape or range). Every case is either scored (counts
that add up) or an :class:`EvalError` of one line naming the file, never another
exception.

The default run tries a small seeded budget (a few seconds each); ``-m slow`` a larger one.
"""

from __future__ import annotations

import json
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import torchsar_eval as te
from tests.eval.test_datasets_fuzz_coco_voc import MUTATION, TEXT_VALUES, mutate_coco
from torchsar_eval.errors import EvalError

SIZE = 32
GT = {
    "images": [
        {"id": 1, "file_name": "a.png", "height": SIZE, "width": SIZE},
        {"id": 2, "file_name": "b.png", "height": SIZE, "width": SIZE},
    ],
    "categories": [{"id": 1, "name": "ship"}, {"id": 2, "name": "boat"}],
    "annotations": [
        {"id": 1, "image_id": 1, "category_id": 1, "bbox": [2, 2, 8, 8], "area": 64, "iscrowd": 0},
        {
            "id": 2,
            "image_id": 2,
            "category_id": 2,
            "bbox": [10, 10, 6, 5],
            "area": 30,
            "iscrowd": 0,
        },
    ],
}
RESULTS = [
    {"image_id": 1, "category_id": 1, "bbox": [2.5, 2, 8, 8], "score": 0.9},
    {"image_id": 2, "category_id": 2, "bbox": [10, 10, 6, 5], "score": 0.4},
    {"image_id": 2, "category_id": 1, "bbox": [20, 20, 4, 4], "score": 0.2},
]
POINTS = "image_id,row,col,score,length_m\n1,5.5,5.5,0.9,10\n2,12,12,0.4,\n2,25,25,0.2,3\n"


def _score(gt: Path, pred: Path, matching: te.Matching) -> str:
    """``"valid"`` or ``"error"``; raises on a contract breach."""
    try:
        saved = te.predictions(pred, name="p", threshold=0.5)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = te.evaluate(
                {"gt": f"coco:{gt}"},
                [saved],
                progress=False,
                scoring=te.Scoring(matching=matching, replicates=0),
            )
    except EvalError as exc:
        message = str(exc)
        assert "\n" not in message and len(message) < 2000, message[:3000]
        assert pred.name in message or str(pred.parent) in message, message
        return "error"
    row = res.summary.iloc[0]
    assert row.targets == 2 and 0 <= row.tp <= row.targets and row.fp >= 0
    assert row.tp + row.fn == row.targets
    return "valid"


def _folder(tmp: str) -> Path:
    root = Path(tmp)
    (root / "gt.json").write_text(json.dumps(GT))
    return root


def check_results(mutations) -> str:
    text = mutate_coco({"r": RESULTS}, mutations)
    try:  # (the mutator works on a document; the results file is its list)
        doc = json.loads(text)
        text = json.dumps(doc["r"]) if isinstance(doc, dict) and "r" in doc else text
    except (ValueError, RecursionError):
        pass
    with tempfile.TemporaryDirectory() as tmp:
        root = _folder(tmp)
        (root / "results.json").write_text(text)
        return _score(root / "gt.json", root / "results.json", te.Matching(kind="box"))


def mutate_csv(text: str, mutations) -> str:
    """The CSV text after ``mutations`` (cells replaced, rows or columns removed or
    repeated, the header changed, text cut short)."""
    rows = [line.split(",") for line in text.splitlines()]
    cut = None
    for op, where, which, frac in mutations:
        r = rows[where % len(rows)] if rows else None
        if r is None:
            break
        c = (where // 7) % max(len(r), 1)
        if op in ("replace", "stringify") and r:
            r[c] = TEXT_VALUES[which % len(TEXT_VALUES)].replace(",", ";")
        elif op == "delete" and len(r) > 1:
            for row in rows:
                if c < len(row):
                    del row[c]
        elif op == "repeat":
            rows.insert(where % len(rows), list(r))
        elif op == "wrap" and r:
            r[c] = f'"{r[c]}"'
        elif op == "truncate":
            cut = frac
    out = "\n".join(",".join(row) for row in rows) + "\n"
    return out if cut is None else out[: int(len(out) * cut)]


def check_points(mutations) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        root = _folder(tmp)
        (root / "points.csv").write_text(mutate_csv(POINTS, mutations))
        rule = te.Matching(kind="distance", max_distance=3)
        return _score(root / "gt.json", root / "points.csv", rule)


MASK_DTYPES = [
    np.bool_,
    np.int8,
    np.uint8,
    np.uint16,
    np.int32,
    np.int64,
    np.float32,
    np.float64,
    np.complex64,
]
MASK_VALUES = [0, 1, 2, -1, 255, 2**31 - 1, 2**40, np.nan, np.inf, 0.7]
MASK_SHAPES = [(SIZE, SIZE), (1, SIZE, SIZE), (SIZE, SIZE + 1), (SIZE,), (), (2, SIZE, SIZE)]
SCORES = [
    '{"1": 0.7}',
    "{}",
    '{"1": "x"}',
    '{"x": 1}',
    "[1]",
    "",
    "{",
    '{"1": 1e400}',
    "[" * 50_000,
    '{"1": ' + "9" * 5000 + "}",
]
MASK_CASES = st.tuples(
    st.sampled_from(MASK_DTYPES),
    st.sampled_from(MASK_VALUES),
    st.sampled_from(MASK_SHAPES),
    st.sampled_from(SCORES),
    st.booleans(),
)


def check_masks(dtype, value, shape, scores, both) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        root = _folder(tmp)
        folder = root / "masks"
        folder.mkdir()
        good = np.zeros((SIZE, SIZE), np.int32)
        good[2:10, 2:10] = 1
        with np.errstate(invalid="ignore", over="ignore"):
            bad = np.zeros(shape, np.float64)
            if bad.size:
                bad.reshape(-1)[: max(bad.size // 4, 1)] = value
            bad = (
                bad.astype(dtype)
                if not (np.isnan(value) and dtype not in (np.float32, np.float64, np.complex64))
                else bad
            )
        np.save(folder / "a.npy", good)
        np.save(folder / "b.npy", bad)
        (folder / "b.scores.json").write_text(scores)
        if both:
            (folder / "a.scores.json").write_text(scores)
        return _score(root / "gt.json", folder, te.Matching(kind="mask"))


RESULT_CASES = st.lists(MUTATION, min_size=1, max_size=3)


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(RESULT_CASES)
def test_results_reader_is_scored_or_one_named_error(case):
    check_results(case)


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(RESULT_CASES)
def test_points_reader_is_scored_or_one_named_error(case):
    check_points(case)


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(MASK_CASES)
def test_mask_folder_is_scored_or_one_named_error(case):
    check_masks(*case)


@pytest.mark.slow
@settings(max_examples=1500, deadline=None, derandomize=True, database=None)
@given(RESULT_CASES)
def test_results_reader_fuzzed_longer(case):
    check_results(case)


@pytest.mark.slow
@settings(max_examples=1500, deadline=None, derandomize=True, database=None)
@given(RESULT_CASES)
def test_points_reader_fuzzed_longer(case):
    check_points(case)


@pytest.mark.slow
@settings(max_examples=600, deadline=None, derandomize=True, database=None)
@given(MASK_CASES)
def test_mask_folder_fuzzed_longer(case):
    check_masks(*case)


def test_unmutated_inputs_are_valid():
    """The fuzzers start from inputs the readers accept as they are."""
    assert check_results([]) == "valid"
    assert check_points([]) == "valid"
    assert check_masks(np.int32, 1, (SIZE, SIZE), '{"1": 0.7}', False) == "valid"
