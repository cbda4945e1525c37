"""Mutation fuzzing of the COCO and VOC readers: a valid annotation file with a few fields
changed (types swapped, NaN / inf / huge / negative numbers, keys removed, elements
repeated, text cut short, nesting deepened). Every case is either a valid dataset whose
items agree with the mutated file, or an EvalError of one line naming the file, never
another exception.

The default run tries a small seeded budget (a few seconds); ``-m slow`` a larger one.
"""

from __future__ import annotations

import copy
import json
import math
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.eval.coco_voc_inputs import (
    SIZE,
    coco_doc,
    load_everything,
    voc_text,
    write_coco_file,
    write_voc_folder,
)
from torchsar_eval.errors import EvalError

DIGITS, NEST = "__DIGITS__", "__NEST__"
JSON_VALUES = [
    math.nan,
    math.inf,
    -math.inf,
    1e300,
    -1e300,
    -1,
    0,
    0.5,
    3,
    31,
    33,
    10**30,
    "x",
    "",
    "7",
    None,
    True,
    [],
    {},
    [[1, 2]],
    [0, 0, 1, 0, 1, 1],
    {"size": [SIZE, SIZE], "counts": "0"},
    "../b.png",
    DIGITS,
    NEST,
]
TEXT_VALUES = [
    "nan",
    "inf",
    "-inf",
    "1e300",
    "1e400",
    "-5",
    "0",
    "0.5",
    "",
    "abc",
    "9" * 5000,
    "  3  ",
    "1",
    "40",
    "../b.png",
    "/etc/hostname",
]
OPS = ("replace", "replace", "delete", "repeat", "wrap", "stringify", "truncate")

MUTATION = st.tuples(
    st.sampled_from(OPS),
    st.integers(0, 10**6),  # which node
    st.integers(0, 10**6),  # which value
    st.floats(0.05, 0.95),  # where to cut
)
COCO_CASES = st.tuples(st.sampled_from([1, 2]), st.lists(MUTATION, min_size=1, max_size=3))
VOC_CASES = st.lists(MUTATION, min_size=1, max_size=3)


# --- mutations ---------------------------------------------------------------------------


def _json_nodes(node, out: list) -> list:
    """Every ``(container, key)`` below ``node``, depth first."""
    items = node.items() if isinstance(node, dict) else enumerate(node)
    for key, value in items:
        out.append((node, key))
        if isinstance(value, dict | list):
            _json_nodes(value, out)
    return out


def mutate_coco(doc: dict, mutations) -> str:
    """The COCO file text after ``mutations``."""
    doc = copy.deepcopy(doc)
    cut = None
    for op, where, which, frac in mutations:
        nodes = _json_nodes(doc, [])
        if not nodes:
            break
        parent, key = nodes[where % len(nodes)]
        if op == "replace":
            parent[key] = copy.deepcopy(JSON_VALUES[which % len(JSON_VALUES)])
        elif op == "delete":
            del parent[key]
        elif op == "repeat" and isinstance(parent, list):
            parent.insert(key, copy.deepcopy(parent[key]))
        elif op == "repeat":  # a dict: the value of another node in its place
            other, k = nodes[which % len(nodes)]
            parent[key] = copy.deepcopy(other[k])
        elif op == "wrap":
            parent[key] = [parent[key]]
        elif op == "stringify":
            parent[key] = json.dumps(parent[key])
        elif op == "truncate":
            cut = frac
    text = json.dumps(doc)
    text = text.replace(f'"{DIGITS}"', "9" * 5000)
    text = text.replace(f'"{NEST}"', "[" * 50_000 + "]" * 50_000)
    return text if cut is None else text[: int(len(text) * cut)]


def mutate_voc(xml: str, mutations) -> str:
    """The VOC file text after ``mutations``."""
    root = ET.fromstring(xml)
    cut = None
    for op, where, which, frac in mutations:
        pairs = [(p, c) for p in root.iter() for c in p]
        if not pairs:
            break
        parent, child = pairs[where % len(pairs)]
        if op in ("replace", "stringify"):
            child.text = TEXT_VALUES[which % len(TEXT_VALUES)]
        elif op == "delete":
            parent.remove(child)
        elif op == "repeat":
            parent.append(copy.deepcopy(child))
        elif op == "wrap":
            parent.remove(child)
            ET.SubElement(parent, "wrapper").append(child)
        elif op == "truncate":
            cut = frac
    text = ET.tostring(root, encoding="unicode")
    return text if cut is None else text[: int(len(text) * cut)]


VOC_BASE = voc_text(objects=(("ship", (3, 2, 10, 8), 0), ("boat", (20, 20, 26, 24), 1)))


# --- the contract ------------------------------------------------------------------------


def _expected_coco(text: str) -> dict:
    """Per image id: the non-crowd annotations' category names, from the mutated file
    read independently (the reader accepted it, so it must be plain COCO)."""
    doc = json.loads(text)
    names = {c["id"]: c["name"] for c in doc.get("categories", [])}
    out: dict = {im["id"]: [] for im in doc["images"]}
    for a in doc.get("annotations", []):
        if not a.get("iscrowd", 0):
            out[a["image_id"]].append(names[a["category_id"]])
    return out


def _expected_voc(text: str) -> list[str]:
    root = ET.fromstring(text)
    return [
        (o.findtext("name") or "").strip()
        for o in root.iter("object")
        if (o.findtext("difficult") or "0").strip() != "1"
    ]


def _check_item(item: dict, classes: list[str]) -> None:
    """What a valid item must be: shapes, dtypes, ids within the objects, boxes inside,
    one class and box per non-ignored object of the file."""
    image, inst, ignore = item["image"], item["instances"], item["ignore"]
    assert image.shape == inst.shape == ignore.shape == (1, SIZE, SIZE)
    assert bool((image >= 0).all()) and bool(image.isfinite().all())
    meta = item["meta"]
    assert meta["classes"] == classes
    assert len(meta["boxes"]) == len(classes)
    assert int(inst.min()) >= 0 and int(inst.max()) <= len(classes)
    for r0, c0, r1, c1 in meta["boxes"]:
        assert all(map(math.isfinite, (r0, c0, r1, c1)))
        assert 0 <= r0 <= r1 <= SIZE and 0 <= c0 <= c1 <= SIZE


def check_coco(n_images: int, mutations) -> str:
    """One COCO case: ``"valid"`` or ``"error"``; raises on a contract breach."""
    text = mutate_coco(coco_doc(n_images), mutations)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        path = write_coco_file(root, text, names=("a.png", "b.png")[:n_images])
        try:
            items = load_everything(f"coco:{path}?type=amplitude")
        except EvalError as exc:
            _check_message(str(exc), root, "ann.json")
            return "error"
    expected = _expected_coco(text)
    for item in items:
        _check_item(item, expected[item["meta"]["image_id"]])
    return "valid"


def check_voc(mutations) -> str:
    """One VOC case: ``"valid"`` or ``"error"``; raises on a contract breach."""
    text = mutate_voc(VOC_BASE, mutations)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        write_voc_folder(root, text)
        try:
            items = load_everything(f"voc:{root}?type=amplitude")
        except EvalError as exc:
            _check_message(str(exc), root, "a.xml")
            return "error"
    (item,) = items
    _check_item(item, _expected_voc(text))
    return "valid"


def _check_message(message: str, root: Path, annotation_file: str) -> None:
    """One line naming the annotation file or a file under the dataset's folder."""
    assert "\n" not in message, message
    assert annotation_file in message or str(root) in message, message


# --- the fuzzers -------------------------------------------------------------------------


@settings(max_examples=120, deadline=None, derandomize=True, database=None)
@given(COCO_CASES)
def test_coco_reader_is_valid_or_one_named_error(case):
    check_coco(*case)


@settings(max_examples=80, deadline=None, derandomize=True, database=None)
@given(VOC_CASES)
def test_voc_reader_is_valid_or_one_named_error(case):
    check_voc(case)


@pytest.mark.slow
@settings(max_examples=3000, deadline=None, derandomize=True, database=None)
@given(COCO_CASES)
def test_coco_reader_fuzzed_longer(case):
    check_coco(*case)


@pytest.mark.slow
@settings(max_examples=1500, deadline=None, derandomize=True, database=None)
@given(VOC_CASES)
def test_voc_reader_fuzzed_longer(case):
    check_voc(case)


def test_unmutated_inputs_are_valid():
    """The fuzzers start from inputs the readers accept as they are."""
    assert check_coco(2, []) == "valid"
    assert check_voc([]) == "valid"
