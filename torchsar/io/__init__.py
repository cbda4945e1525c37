"""Readers of SAR data files: rasters, annotations, MSTAR Phoenix, SICD, GOTCHA, and
windowed readers of whole scenes (:func:`open_scene`)."""

from torchsar.io.channels import single_channel
from torchsar.io.coco import (
    CocoAnnotation,
    CocoImage,
    CocoSet,
    CocoTable,
    annotation_mask,
    read_coco,
    read_coco_table,
)
from torchsar.io.errors import AnnotationWarning, FileFormatError
from torchsar.io.georef import AffineGeoref, GeorefError, TiePointGrid
from torchsar.io.geotiff import geotiff_pixel_spacing
from torchsar.io.gotcha import GotchaPass, gotcha_files, read_gotcha
from torchsar.io.idmap import decode_id_map
from torchsar.io.phoenix import PhoenixChip, is_phoenix, read_phoenix, read_phoenix_header
from torchsar.io.raster import (
    DEFAULT_MAX_PIXELS,
    RASTER_EXTS,
    TIFF_EXTS,
    check_regular_file,
    raster_shape,
    read_raster,
    tiff_dtype,
)
from torchsar.io.scaling import SAMPLE_TYPES, to_intensity
from torchsar.io.scene import open_scene
from torchsar.io.scene_reader import SceneReader
from torchsar.io.sicd import SicdChip, SicdScene, read_sicd, sicd_shape
from torchsar.io.tiff_scene import TiffScene
from torchsar.io.voc import VocAnnotation, VocObject, read_voc
from torchsar.io.window import WindowError

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "RASTER_EXTS",
    "SAMPLE_TYPES",
    "TIFF_EXTS",
    "AffineGeoref",
    "AnnotationWarning",
    "CocoAnnotation",
    "CocoImage",
    "CocoSet",
    "CocoTable",
    "FileFormatError",
    "GeorefError",
    "GotchaPass",
    "PhoenixChip",
    "SceneReader",
    "SicdChip",
    "SicdScene",
    "TiePointGrid",
    "TiffScene",
    "VocAnnotation",
    "VocObject",
    "WindowError",
    "annotation_mask",
    "check_regular_file",
    "decode_id_map",
    "geotiff_pixel_spacing",
    "gotcha_files",
    "is_phoenix",
    "open_scene",
    "raster_shape",
    "read_coco",
    "read_coco_table",
    "read_gotcha",
    "read_phoenix",
    "read_phoenix_header",
    "read_raster",
    "read_sicd",
    "read_voc",
    "sicd_shape",
    "single_channel",
    "tiff_dtype",
    "to_intensity",
]
