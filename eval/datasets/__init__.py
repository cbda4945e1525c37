"""Datasets of the harness: simulated chips and scenes, image folders, COCO, VOC, HRSID and
MSTAR Phoenix files and SICD products.

Every dataset yields dicts with ``image`` ``(C, H, W)`` float32 intensity (converted once
from the declared sample type by :func:`torchsar.io.to_intensity`), ``mask`` ``(C, H, W)``
bool target pixels, ``instances`` ``(C, H, W)`` int32 ids ``1..K``, ``ignore`` ``(C, H, W)``
bool don't-care pixels and ``meta``: ``name`` (unique), ``classes`` and ``boxes`` (one per
id, ``(r0, c0, r1, c1)`` end-exclusive), ``gt`` (``mask`` or ``box``: match box-only ground
truth by box IoU), ``class`` (image-level, or ``None``), ``pixel_spacing`` (``(row_m, col_m)``
or ``None``), ``sample_type`` and ``path``. File datasets also offer ``options`` (resolved
options, for ``config.json``) and ``manifest()`` (file count, bytes, hash of the file list).

Names accepted by :func:`make_dataset` (options as ``?key=value&key=value``):

- ``sim-chips``, ``sim-scenes``: simulated intensity, items generated on demand.
- ``folder:PATH``: ``<stem>.mask.png`` label maps (0 clutter, 1 target, 2 shadow) beside
  ``<stem>.png|jpg|jpeg|tif|tiff`` images; ``variant=linear`` picks ``<stem>.linear.jpeg``.
- ``coco:FILE.json``: COCO boxes, polygons and RLE; ``images=DIR`` (default: the JSON's folder).
- ``voc:DIR``: Pascal VOC XML boxes (``gt="box"``); images in ``images=DIR``, VOC's
  ``JPEGImages`` or beside the XML. COCO and VOC refuse an image name that resolves
  outside its folder (``..``, an absolute path, a link elsewhere) unless ``outside=allow``.
- ``hrsid:DIR``: HRSID ``<name>.png`` with ``<name>_instance_id_RGB.png`` colour ids.
- ``phoenix:DIR``: MSTAR raw Phoenix files (pixel spacing from the header).
- ``sicd:FILE``: a SICD/NITF complex product cut into ``chip=N`` (512) chips, no ground
  truth (needs the optional sarpy package: ``pip install 'sarpy>=1.3'``).
- ``store:DIR``: a store written by ``torchsar-eval make-dataset`` (see :mod:`torchsar_eval.store`).

Common options: ``type=intensity|amplitude|db|complex|display`` (defaults: 8/16-bit images
``display``, folder ``variant=linear`` ``amplitude``, float TIFF ``intensity``, complex TIFF
``complex``, Phoenix ``amplitude``; ``display`` data get a :class:`DisplayScalingWarning`);
``spacing=ROW[,COL]`` metres (else from the files: Phoenix header, SICD grid, folder
``<stem>.spacing.txt`` sidecar or projected GeoTIFF; else ``None``); ``max_pixels=N``
(default 16,777,216 = 4096 x 4096, sized to the evaluator's memory per image; checked from
the header before decoding); ``n=N``, the dataset's own image count (also on ``sim-chips``
and ``sim-scenes``: ``sim-scenes?n=16``), which takes precedence over ``make_dataset(n=)``
and the CLI's ``--n``.

Folder and Phoenix: ``shadow=ignore|clutter|target`` (what label 2 means; default
``ignore``), ``instances=components|one-per-image|idmap``
(folder default: ``idmap`` when ``<stem>.instances.png`` exist, ``one-per-image`` when every
mask has a ``<stem>.box.txt`` target box as in MSTAR SARBake, else 8-connected
``components``). The image-level class of a folder item is its parent folder's name.
Their items record the choice in ``meta["shadow"]``; ``"ignore"`` (as the simulated data)
tells the scorer that the ignore pixels are radar shadow (the ``shadow`` false-alarm type
of ``errors.csv``). Other datasets have no shadow masks: that type is 0 there.

Building a dataset checks its structure (pairing, annotations) and warns when the
instances of its first readable items look split or merged; an unreadable item raises
:class:`BadItemError` (naming the file, ``.path``) when it is accessed.
"""

from torchsar_eval.datasets.base import BadItemError, DisplayScalingWarning, FileDataset
from torchsar_eval.datasets.folder import FolderDataset
from torchsar_eval.datasets.images import read_image
from torchsar_eval.datasets.make import DATASETS, make_dataset
from torchsar_eval.datasets.manifest import file_manifest
from torchsar_eval.datasets.sim import SimDataset

__all__ = [
    "DATASETS",
    "BadItemError",
    "DisplayScalingWarning",
    "FileDataset",
    "FolderDataset",
    "SimDataset",
    "file_manifest",
    "make_dataset",
    "read_image",
]
