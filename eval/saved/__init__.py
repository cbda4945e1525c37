"""Saved predictions (COCO results, point CSV, mask folders) scored like any detector:
:func:`predictions` makes one a :class:`~torchsar_eval.Detector`."""

from torchsar_eval.saved.detector import FORMATS, SavedPredictions, predictions
from torchsar_eval.saved.keys import dataset_keys, locate
from torchsar_eval.saved.masks import MaskFolder
from torchsar_eval.saved.table import PredictionTable, read_coco_results, read_points

__all__ = [
    "FORMATS",
    "MaskFolder",
    "PredictionTable",
    "SavedPredictions",
    "dataset_keys",
    "locate",
    "predictions",
    "read_coco_results",
    "read_points",
]
