"""Discrimination: a detector's mask becomes scored objects under rules shared by every
detector (closing, connected components, size limits), ready for one-to-one matching."""

from torchsar.objects.components import label_components
from torchsar.objects.discriminate import discriminate, normalised_score
from torchsar.objects.objects import ObjectMasks, Objects
from torchsar.objects.rules import ObjectRules

__all__ = [
    "ObjectMasks",
    "ObjectRules",
    "Objects",
    "discriminate",
    "label_components",
    "normalised_score",
]
