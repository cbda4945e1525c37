"""Pascal VOC XML: 1-based inclusive corners become 0-based end-exclusive boxes."""

from __future__ import annotations

import pytest

from tests.io.writers import voc_xml
from torchsar.io import FileFormatError, read_voc


def test_boxes_names_and_difficult(tmp_path):
    path = tmp_path / "a.xml"
    path.write_text(
        voc_xml("a.jpg", (20, 30), [("ship", (1, 1, 5, 3), 0), ("ship", (10, 4, 30, 20), 1)])
    )
    ann = read_voc(path)
    assert (ann.filename, ann.height, ann.width) == ("a.jpg", 20, 30)
    assert [o.box for o in ann.objects] == [(0, 0, 3, 5), (3, 9, 20, 30)]
    assert [o.difficult for o in ann.objects] == [False, True]
    assert {o.name for o in ann.objects} == {"ship"}


@pytest.mark.parametrize(
    ("xml", "message"),
    [
        (voc_xml("a.jpg", (20, 30), [("ship", (1, 1, 31, 3), 0)]), "lies outside the 30x20 image"),
        (voc_xml("a.jpg", (20, 30), [("ship", (5, 5, 5, 3), 0)]), "or is empty"),
        ("<annotation><filename>a.jpg</filename></annotation>", "lacks <filename> or <size>"),
        ("<annotation", "is not a readable VOC XML file"),
    ],
)
def test_bad_files_are_named(tmp_path, xml, message):
    path = tmp_path / "bad.xml"
    path.write_text(xml)
    with pytest.raises(FileFormatError, match="bad.xml: ") as info:
        read_voc(path)
    assert message in str(info.value)
