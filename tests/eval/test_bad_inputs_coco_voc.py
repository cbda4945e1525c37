"""Crafted COCO and VOC annotation files (and a corrupt TIFF): each must give one typed
error, one line naming the file and the offending field, never a traceback, an
out-of-memory or a silently wrong dataset.

``CASES`` each broke before the readers validated their input (a traceback, a silent
result or a message naming neither the file nor the field); ``GUARDS`` were one-line errors
already and are kept so they stay so.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import textwrap
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tests.eval.coco_voc_inputs import (
    SIZE,
    coco_doc,
    load_everything,
    voc_text,
    write_coco_file,
    write_images,
    write_voc_folder,
)
from tests.io.writers import write_tiff
from torchsar.io import read_coco
from torchsar_eval.cli import main
from torchsar_eval.errors import EvalError

REPO = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Case:
    name: str
    write: Callable[[Path], str]  # writes the files into tmp_path, returns the dataset spec
    error: type[Exception]
    match: str


def coco(mutate: Callable[[dict], object], names=("a.png",)) -> Callable[[Path], str]:
    """A case: the valid COCO file changed by ``mutate(doc)`` (in place)."""

    def write(tmp: Path) -> str:
        doc = coco_doc()
        mutate(doc)
        return f"coco:{write_coco_file(tmp, doc, names)}?type=amplitude"

    return write


def coco_text(text: str) -> Callable[[Path], str]:
    return lambda tmp: f"coco:{write_coco_file(tmp, text)}?type=amplitude"


def voc(xml: str) -> Callable[[Path], str]:
    return lambda tmp: f"voc:{write_voc_folder(tmp, xml)}?type=amplitude"


def ann(k: int, **fields) -> Callable[[dict], None]:
    """Set fields of annotation ``k``."""
    return lambda doc: doc["annotations"][k].update(fields)


def image(**fields) -> Callable[[dict], None]:
    return lambda doc: doc["images"][0].update(fields)


def top(**fields) -> Callable[[dict], None]:
    return lambda doc: doc.update(fields)


def _outside_file(tmp: Path, name: str) -> Path:
    """The image written outside the annotation folder ``tmp/d``."""
    write_images(tmp, (name,))
    return tmp / name


def escaping(kind: str) -> Callable[[Path], str]:
    """A COCO file in ``tmp/d`` naming an image outside ``tmp/d``."""

    def write(tmp: Path) -> str:
        folder = tmp / "d"
        outside = _outside_file(tmp, "x.png")
        doc = coco_doc()
        if kind == "dotdot":
            doc["images"][0]["file_name"] = "../x.png"
        elif kind == "absolute":
            doc["images"][0]["file_name"] = str(outside)
        path = write_coco_file(folder, doc, names=())
        if kind == "symlink":
            (folder / "a.png").symlink_to(outside)
        return f"coco:{path}?type=amplitude"

    return write


def voc_escaping(tmp: Path) -> str:
    """A VOC file naming ``../x.png``: beside ``JPEGImages``, not in it."""
    write_images(tmp, ("x.png",))
    return f"voc:{write_voc_folder(tmp, voc_text(filename='../x.png'), names=())}?type=amplitude"


def zero_d_tiff(tmp: Path) -> str:
    """A COCO image that is a TIFF whose only IFD has no entries: tifffile reads a series
    of shape ``()`` and logs 'invalid page offset'."""
    doc = coco_doc()
    doc["images"][0]["file_name"] = "a.tif"
    path = write_coco_file(tmp, doc, names=())
    _write_zero_d_tiff(tmp / "a.tif")
    return f"coco:{path}?type=amplitude"


def _write_zero_d_tiff(path: Path) -> None:
    write_tiff(path, np.ones((SIZE, SIZE), np.uint8))
    data = bytearray(path.read_bytes())
    assert data[:4] == b"II*\0"
    first_ifd = struct.unpack("<I", data[4:8])[0]
    data[first_ifd : first_ifd + 2] = b"\0\0"  # zero directory entries
    path.write_bytes(bytes(data))


def _compressed_counts(doc: dict, counts: str) -> None:
    doc["annotations"][2]["segmentation"]["counts"] = counts


def _drop_first_count(doc: dict) -> None:
    counts = doc["annotations"][1]["segmentation"]["counts"]
    counts[0] -= 1


def _duplicate_image(same: str) -> Callable[[dict], None]:
    def mutate(doc: dict) -> None:
        twin = dict(doc["images"][0])
        if same == "id":
            twin["file_name"] = "b.png"
        else:
            twin["id"] = 8
        doc["images"].append(twin)

    return mutate


HUGE = 10**6
A = r"ann\.json: "
CASES = [
    Case(
        "coco-bomb-polygon-1e300",
        coco(ann(0, segmentation=[[2, 1, 10, 1, 1e300, 6]])),
        EvalError,
        A + r"annotations\[0\] \(id 1\) segmentation polygon 0 point 2 .*outside "
        r"image a\.png \(32x32\)",
    ),
    Case(
        "coco-polygon-far-outside",
        coco(ann(0, segmentation=[[2, 1, 10, 1, 10, 6e5]])),
        EvalError,
        A + r"annotations\[0\] \(id 1\) segmentation polygon 0 point 2 .*outside",
    ),
    Case(
        "coco-polygon-nan",
        coco(ann(0, segmentation=[[2, 1, float("nan"), 1, 10, 6]])),
        EvalError,
        A + r"annotations\[0\] \(id 1\) segmentation polygon 0 holds nan",
    ),
    Case(
        "coco-polygon-3-numbers",
        coco(ann(0, segmentation=[[2, 1, 10]])),
        EvalError,
        A + r"annotations\[0\] \(id 1\) segmentation polygon 0 has 3 numbers",
    ),
    Case(
        "coco-polygon-odd",
        coco(ann(0, segmentation=[[2, 1, 10, 1, 10, 6, 2]])),
        EvalError,
        A + r"annotations\[0\] \(id 1\) segmentation polygon 0 has 7 numbers",
    ),
    Case(
        "coco-polygon-4-numbers",
        coco(ann(0, segmentation=[[2, 1, 10, 6]])),
        EvalError,
        A + r"annotations\[0\] \(id 1\) segmentation polygon 0 has 4 numbers",
    ),
    Case(
        "coco-polygon-flat",
        coco(ann(0, segmentation=[2, 1, 10, 1, 10, 6])),
        EvalError,
        A + r"annotations\[0\] \(id 1\) segmentation .*polygons",
    ),
    Case(
        "coco-segmentation-integer",
        coco(ann(0, segmentation=5)),
        EvalError,
        A + r"annotations\[0\] \(id 1\) segmentation 5 is neither polygons",
    ),
    Case(
        "coco-rle-string-undecodable",
        coco(lambda d: _compressed_counts(d, "ab~~")),
        EvalError,
        A + r"annotations\[2\] \(id 3\) segmentation counts .*not .*RLE",
    ),
    Case(
        "coco-rle-string-unfinished",
        coco(lambda d: _compressed_counts(d, "PPo")),
        EvalError,
        A + r"annotations\[2\] \(id 3\) segmentation counts .*not .*RLE",
    ),
    Case(
        "coco-rle-string-overflow",
        coco(lambda d: _compressed_counts(d, "o" * 30 + "0")),
        EvalError,
        A + r"annotations\[2\] \(id 3\) segmentation counts .*not .*RLE",
    ),
    Case(
        "coco-rle-string-wrong-sum",
        coco(lambda d: _compressed_counts(d, "52")),
        EvalError,
        A + r"annotations\[2\] \(id 3\) segmentation counts sum to 7, not "
        r"32x32 = 1024",
    ),
    Case(
        "coco-rle-list-wrong-sum",
        coco(_drop_first_count),
        EvalError,
        A + r"annotations\[1\] \(id 2\) segmentation counts sum to 1023, not "
        r"32x32 = 1024",
    ),
    Case(
        "coco-rle-list-negative",
        coco(lambda d: d["annotations"][1]["segmentation"].update(counts=[1025, -1])),
        EvalError,
        A + r"annotations\[1\] \(id 2\) segmentation counts .*non-negative",
    ),
    Case(
        "coco-rle-size-mismatch",
        coco(lambda d: d["annotations"][1]["segmentation"].update(size=[16, 64])),
        EvalError,
        A + r"annotations\[1\] \(id 2\) segmentation size \[16, 64\] is not image "
        r"a\.png's \[32, 32\]",
    ),
    Case(
        "coco-bbox-nan",
        coco(ann(3, bbox=[25, 2, float("nan"), 3])),
        EvalError,
        A + r"annotations\[3\] \(id 4\) bbox .*finite",
    ),
    Case(
        "coco-bbox-huge-int",
        coco(ann(3, bbox=[25, 2, 10**400, 3])),
        EvalError,
        A + r"annotations\[3\] \(id 4\) bbox .*finite",
    ),
    Case(
        "coco-area-nan",
        coco(ann(0, area=float("nan"))),
        EvalError,
        A + r"annotations\[0\] \(id 1\) area nan",
    ),
    Case(
        "coco-iscrowd-string",
        coco(ann(0, iscrowd="no")),
        EvalError,
        A + r"annotations\[0\] \(id 1\) iscrowd 'no' must be 0 or 1",
    ),
    Case(
        "coco-category-id-unhashable",
        coco(ann(0, category_id=[1])),
        EvalError,
        A + r"annotations\[0\] \(id 1\) has unknown category_id \[1\]",
    ),
    Case(
        "coco-image-id-unhashable",
        coco(ann(0, image_id={"a": 1})),
        EvalError,
        A + r"annotations\[0\] \(id 1\) refers to unknown image_id",
    ),
    Case(
        "coco-categories-not-a-list",
        coco(top(categories={"id": 1, "name": "ship"})),
        EvalError,
        A + r"'categories' must be a list",
    ),
    Case(
        "coco-category-without-name",
        coco(lambda d: d["categories"][1].pop("name")),
        EvalError,
        A + r"categories\[1\] has no name",
    ),
    Case(
        "coco-annotation-not-an-object",
        coco(lambda d: d["annotations"].insert(0, 3)),
        EvalError,
        A + r"annotations\[0\] is not an object",
    ),
    Case(
        "coco-annotations-not-a-list",
        coco(top(annotations={"id": 1})),
        EvalError,
        A + r"'annotations' must be a list",
    ),
    Case(
        "coco-deep-nesting",
        coco_text("[" * 100_000 + "]" * 100_000),
        EvalError,
        A + r"is not a readable JSON file \(nested too deeply\)",
    ),
    Case(
        "coco-5000-digit-number",
        coco_text('{"images": [{"id": ' + "7" * 5000 + ', "file_name": "a.png"}]}'),
        EvalError,
        A + r"is not a readable JSON file \(.*digits",
    ),
    Case(
        "coco-height-fraction",
        coco(image(height=32.5)),
        EvalError,
        A + r"images\[0\] \(id 7\) height 32\.5 must be a positive integer",
    ),
    Case(
        "coco-height-string",
        coco(image(height="32")),
        EvalError,
        A + r"images\[0\] \(id 7\) height '32' must be a positive integer",
    ),
    Case(
        "coco-image-huge",
        coco(image(height=HUGE, width=HUGE)),
        EvalError,
        A + r"images\[0\] \(id 7\) a\.png is 1000000x1000000 = 1,000,000,000,000 "
        r"pixels, over the limit of 16,777,216",
    ),
    Case(
        "coco-file-name-dotdot",
        escaping("dotdot"),
        EvalError,
        r"ann\.json: images\[0\] \(id 7\) file_name '\.\./x\.png' .*outside the "
        r"image folder .*outside=allow",
    ),
    Case(
        "coco-file-name-absolute",
        escaping("absolute"),
        EvalError,
        r"ann\.json: images\[0\] \(id 7\) file_name '/.*x\.png' .*outside the image "
        r"folder",
    ),
    Case(
        "coco-file-name-symlink-escapes",
        escaping("symlink"),
        EvalError,
        r"ann\.json: images\[0\] \(id 7\) file_name 'a\.png' .*x\.png, outside the "
        r"image folder",
    ),
    Case(
        "coco-same-image-id-twice",
        coco(_duplicate_image("id"), ("a.png", "b.png")),
        EvalError,
        A + r"images\[0\] and images\[1\] both have id 7 \(a\.png, b\.png\)",
    ),
    Case(
        "coco-tiff-0-d", zero_d_tiff, EvalError, r"a\.tif: holds no 2-D image \(header shape \(\)"
    ),
    Case(
        "voc-height-nan",
        voc(voc_text(size=("nan", SIZE))),
        EvalError,
        r"a\.xml: <size> <height> 'nan' must be a positive integer",
    ),
    Case(
        "voc-height-negative",
        voc(voc_text(size=(-32, SIZE))),
        EvalError,
        r"a\.xml: <size> <height> '-32' must be a positive integer",
    ),
    Case(
        "voc-width-fraction",
        voc(voc_text(size=(SIZE, "31.5"))),
        EvalError,
        r"a\.xml: <size> <width> '31\.5' must be a positive integer",
    ),
    Case(
        "voc-size-huge",
        voc(voc_text(size=(HUGE, HUGE), objects=())),
        EvalError,
        r"a\.xml: <size> is 1000000x1000000 = 1,000,000,000,000 pixels, over the "
        r"limit of 16,777,216",
    ),
    Case(
        "voc-filename-dotdot",
        voc_escaping,
        EvalError,
        r"a\.xml: <filename> '\.\./x\.png' .*outside the image folder",
    ),
]

GUARDS = [
    Case("coco-two-ids-one-file", coco(_duplicate_image("file_name")), EvalError, r"a\.png"),
    Case("coco-top-level-list", coco_text("[]"), EvalError, A + r"is not a COCO annotation"),
    Case("coco-not-json", coco_text("{nope"), EvalError, A + r"is not a readable JSON file"),
    Case(
        "coco-box-outside",
        coco(ann(3, bbox=[30, 2, 4, 3])),
        EvalError,
        A + r"annotation.*4.* box .*outside image a\.png",
    ),
    Case(
        "voc-height-not-a-number",
        voc(voc_text(size=("abc", SIZE))),
        EvalError,
        r"a\.xml: .*<height>",
    ),
    Case(
        "voc-box-nan",
        voc(voc_text(objects=(("ship", ("nan", 2, 10, 8), 0),))),
        EvalError,
        r"a\.xml: .*xmin",
    ),
    Case(
        "voc-box-outside",
        voc(voc_text(objects=(("ship", (3, 2, 40, 8), 0),))),
        EvalError,
        r"a\.xml: box of 'ship' .*outside",
    ),
]


@pytest.mark.parametrize("case", CASES + GUARDS, ids=lambda c: c.name)
def test_bad_input_gives_one_typed_error_naming_file_and_field(case, tmp_path):
    spec = case.write(tmp_path)
    with pytest.raises(case.error, match=case.match) as info:
        load_everything(spec)
    assert "\n" not in str(info.value)


def test_every_case_name_is_unique():
    names = [c.name for c in CASES + GUARDS]
    assert len(names) == len(set(names))


def test_escaping_file_name_is_read_when_allowed(tmp_path):
    spec = escaping("dotdot")(tmp_path)
    (item,) = load_everything(spec + "&outside=allow")
    assert item["meta"]["path"].endswith("x.png")


def test_symlink_inside_the_folder_is_fine(tmp_path):
    """A link to another file of the folder stays inside it."""
    folder = tmp_path / "d"
    path = write_coco_file(folder, coco_doc(), names=("real.png",))
    (folder / "a.png").symlink_to(folder / "real.png")
    (item,) = load_everything(f"coco:{path}?type=amplitude")
    assert item["meta"]["classes"] == ["ship", "boat", "ship", "boat"]


def test_polygon_on_the_border_is_within_tolerance(tmp_path):
    """Vertices on the image border (x = width) and up to one pixel beyond are accepted."""
    doc = coco_doc()
    doc["annotations"] = doc["annotations"][:1]
    doc["annotations"][0]["segmentation"] = [[-1, -1, SIZE + 1, -1, SIZE + 1, 6, -1, 6]]
    doc["annotations"][0]["bbox"] = [0, 0, SIZE, 6]
    (item,) = load_everything(f"coco:{write_coco_file(tmp_path, doc)}?type=amplitude")
    inst = item["instances"][0].numpy()
    assert (inst[:6] == 1).all() and (inst[6:] == 0).all()  # the band y < 6, clipped


def test_duplicate_annotation_ids_warn_naming_them(tmp_path):
    from torchsar.io import AnnotationWarning

    doc = coco_doc()
    doc["annotations"][1]["id"] = 1
    with pytest.warns(
        AnnotationWarning,
        match=r"ann\.json: annotations\[0\] and "
        r"annotations\[1\] both have id 1",
    ):
        coco_set = read_coco(write_coco_file(tmp_path, doc))
    assert len(coco_set.images[0].annotations) == 5  # both kept


def test_tiff_log_messages_become_the_error_text(tmp_path, caplog, capfd):
    """tifffile's complaint is in the error, not in the log nor on stderr."""
    spec = zero_d_tiff(tmp_path)
    with pytest.raises(EvalError, match=r"a\.tif: .*tifffile: invalid page offset"):
        load_everything(spec)
    assert not [r for r in caplog.records if r.name.startswith("tifffile")]
    assert "tifffile" not in capfd.readouterr().err


# --- the command line: exit 2, one line on stderr -----------------------------------------


def _one_line(capsys) -> str:
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1, lines
    assert lines[0].startswith("torchsar-eval: error: ")
    return lines[0]


def _run(spec: str, out: Path, *extra: str) -> int:
    return main(
        ["run", "--dataset", spec, "--detectors", "ca", "--out", str(out), "--no-progress", *extra]
    )


@pytest.mark.parametrize(
    "name",
    [
        "coco-bomb-polygon-1e300",
        "coco-rle-size-mismatch",
        "coco-deep-nesting",
        "voc-height-nan",
        "coco-file-name-dotdot",
        "coco-tiff-0-d",
    ],
)
def test_cli_exits_2_with_one_line(name, tmp_path, capsys):
    case = next(c for c in CASES if c.name == name)
    spec = case.write(tmp_path)
    assert _run(spec, tmp_path / "out") == 2
    line = _one_line(capsys)
    assert any(s in line for s in ("ann.json", "a.xml", "a.tif")), line
    assert not (tmp_path / "out").exists()


def test_cli_skip_bad_skips_the_0_d_tiff(tmp_path, capsys):
    doc = coco_doc(n_images=2)
    doc["images"][0]["file_name"] = "a.tif"
    path = write_coco_file(tmp_path, doc, names=("b.png",))
    _write_zero_d_tiff(tmp_path / "a.tif")
    out, spec = tmp_path / "out", f"coco:{path}?type=amplitude"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert _run(spec, out, "--skip-bad") == 0
    err = capsys.readouterr().err
    assert "tifffile" not in err and "Traceback" not in err
    config = json.loads((out / "config.json").read_text())
    (skipped,) = config["options"]["throughput"][spec]["skipped_items"]
    assert skipped["file"] == str(tmp_path / "a.tif")
    assert "holds no 2-D image" in skipped["error"]


# --- resources: the COCO bomb under a memory limit -----------------------------------------

BOMB_SCRIPT = textwrap.dedent(
    """
    import json, sys, warnings
    from pathlib import Path
    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.errors import EvalError
    root = Path(sys.argv[1])
    warnings.simplefilter("ignore")
    try:
        ds = make_dataset(f"coco:{root / 'ann.json'}?type=amplitude")
        [ds[i] for i in range(len(ds))]
    except EvalError as exc:
        print("EvalError:", exc)
        sys.exit(2)
    print("no error")
    """
)


@pytest.mark.integration
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS is Linux only")
def test_coco_bomb_under_a_memory_limit(tmp_path):
    """A 200-byte COCO file with a polygon vertex at 1e300: one error line, no MemoryError,
    no segfault, with the address space limited to 2 GiB above what the interpreter holds."""
    import resource

    text = (
        '{"images":[{"id":1,"file_name":"a.png","height":32,"width":32}],"annotations":'
        '[{"image_id":1,"category_id":1,"bbox":[0,0,1,1],"segmentation":'
        '[[0,0,1,0,1e300,1]]}],"categories":[{"id":1,"name":"s"}]}'
    )
    assert len(text) <= 200
    write_coco_file(tmp_path, text)
    # torch maps a lot of address space at import: measure it, then allow 2 GiB more
    probe = subprocess.run(
        [
            sys.executable,
            "-c",
            "import torchsar_eval.datasets, resource, os;"
            "print(int(open('/proc/self/statm').read().split()[0]) * os.sysconf('SC_PAGE_SIZE'))",
        ],
        capture_output=True,
        text=True,
        check=True,
        cwd=REPO,
    )
    limit = int(probe.stdout) + 2 * 2**30

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    env = dict(os.environ, OMP_NUM_THREADS="1")
    done = subprocess.run(
        [sys.executable, "-c", BOMB_SCRIPT, str(tmp_path)],
        capture_output=True,
        text=True,
        preexec_fn=cap,
        timeout=120,
        cwd=REPO,
        env=env,
    )
    assert done.returncode == 2, (done.returncode, done.stdout[-500:], done.stderr[-2000:])
    lines = done.stdout.strip().splitlines()
    assert len(lines) == 1 and "ann.json: annotations[0] segmentation polygon 0 point 2" in lines[0]
    assert "MemoryError" not in done.stderr and "Traceback" not in done.stderr


# --- saved predictions (COCO results) ------------------------------------------------------


def _predictions(tmp: Path, segmentations: list) -> tuple[str, Path]:
    """The valid ground truth and a results file with one detection per segmentation."""
    gt = write_coco_file(tmp, coco_doc())
    rows = [
        {"image_id": 7, "category_id": 1, "score": 0.5 + 0.1 * k, "segmentation": s}
        for k, s in enumerate(segmentations)
    ]
    dets = tmp / "dets.json"
    dets.write_text(json.dumps(rows))
    return f"coco:{gt}?type=amplitude", dets


@pytest.mark.parametrize(
    ("seg", "message"),
    [
        ([[2, 1, 10, 1, 1e300, 6]], r"entry 1 segmentation polygon 0 point 2 .*outside"),
        ([[2, 1, 10, 1, float("nan"), 6]], r"entry 1 segmentation polygon 0 holds nan"),
        ({"size": [SIZE, SIZE], "counts": [5, 3]}, r"entry 1 segmentation counts sum to 8"),
        ({"size": [SIZE, SIZE], "counts": "PPo"}, r"entry 1 segmentation counts .*not .*RLE"),
    ],
)
def test_bad_predicted_segmentations_are_named(tmp_path, seg, message):
    import torchsar_eval as te

    spec, dets = _predictions(tmp_path, [[[2, 1, 10, 1, 10, 6, 2, 6]], seg])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(EvalError, match=r"predictions .*dets\.json: " + message) as info:
            te.evaluate(spec, [te.predictions(dets)], progress=False)
    assert "\n" not in str(info.value)


def test_predicted_polygon_reaching_outside_is_clipped_as_pycocotools_does(tmp_path):
    """A detection at the border may reach outside the image: decoded as pycocotools
    decodes it."""
    from pycocotools import mask as mask_utils

    from torchsar_eval.saved.detector import segmentation_pixels

    poly = [[-5, -5, 40, -5, 40, 3, -5, 3]]
    _, pixels = segmentation_pixels([poly], SIZE, SIZE)
    with warnings.catch_warnings():  # pycocotools predates numpy 2's copy keyword
        warnings.simplefilter("ignore", DeprecationWarning)
        ref = mask_utils.decode(mask_utils.merge(mask_utils.frPyObjects(poly, SIZE, SIZE)))
    np.testing.assert_array_equal(np.sort(pixels), np.flatnonzero(ref.astype(bool)))


def test_an_image_record_listed_twice_is_read_once_with_a_warning(tmp_path):
    from torchsar.io import AnnotationWarning

    doc = coco_doc()
    doc["images"].append(dict(doc["images"][0]))
    with pytest.warns(
        AnnotationWarning,
        match=r"ann\.json: images\[0\] is listed again as "
        r"images\[1\]",
    ):
        coco_set = read_coco(write_coco_file(tmp_path, doc))
    assert [im.file_name for im in coco_set.images] == ["a.png"]
    assert len(coco_set.images[0].annotations) == 5
