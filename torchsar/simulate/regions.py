"""Heterogeneous clutter backgrounds: Voronoi patches of field/forest and a straight road.

Region means (dB over a 0 dB reference): field ``U(-3, 0)``, forest ``U(1, 4)``, road
``U(-6, -4)``; so neighbouring means differ by up to 10 dB, with sharp (polygonal) edges.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar.seeding import Draws

__all__ = ["MEAN_DB", "background", "edge_pixels"]

MEAN_DB = {"field": (-3.0, 0.0), "forest": (1.0, 4.0), "road": (-6.0, -4.0)}
"""dB range of the mean intensity of each region kind."""


def _voronoi(size: tuple[int, int], k: int, draws: Draws) -> tuple[Tensor, list[dict]]:
    """Label map of ``k`` Voronoi cells with random seeds; one description per cell."""
    H, W = size
    dev = draws.generator.device
    rows, cols = draws.uniform(0, H, k), draws.uniform(0, W, k)
    cells = []
    for i in range(k):
        kind = "forest" if draws.uniform(0.0, 1.0) < 0.5 else "field"
        mean_db = draws.uniform(*MEAN_DB[kind])
        cells.append({"id": i, "kind": kind, "mean_db": mean_db, "seed_rc": (rows[i], cols[i])})
    r = torch.arange(H, device=dev, dtype=torch.float32)[:, None]
    c = torch.arange(W, device=dev, dtype=torch.float32)[None, :]
    best = torch.full((H, W), float("inf"), device=dev)
    labels = torch.zeros((H, W), dtype=torch.int64, device=dev)
    for i in range(k):  # running nearest seed (first seed wins ties, like argmin)
        d = (r - rows[i]) ** 2 + (c - cols[i]) ** 2
        closer = d < best
        best = torch.where(closer, d, best)
        labels = torch.where(closer, i, labels)
    return labels, cells


def _road(size: tuple[int, int], draws: Draws) -> tuple[Tensor, dict]:
    """Mask of a straight road strip 6–14 px wide crossing the central half of the image."""
    H, W = size
    dev = draws.generator.device
    angle = draws.uniform(0.0, math.pi)
    pr, pc = draws.uniform(0.25 * H, 0.75 * H), draws.uniform(0.25 * W, 0.75 * W)
    width = draws.uniform(6.0, 14.0)
    mean_db = draws.uniform(*MEAN_DB["road"])
    r = torch.arange(H, device=dev, dtype=torch.float32)[:, None] - pr
    c = torch.arange(W, device=dev, dtype=torch.float32)[None, :] - pc
    dist = r * math.cos(angle) - c * math.sin(angle)  # signed distance to the centre line
    desc = {
        "kind": "road",
        "mean_db": mean_db,
        "angle_deg": math.degrees(angle),
        "point_rc": (pr, pc),
        "width_px": width,
    }
    return dist.abs() <= 0.5 * width, desc


def background(
    size: tuple[int, int], regions: tuple[int, int], road: bool, draws: Draws
) -> tuple[Tensor, Tensor, dict]:
    """Clean clutter mean ``(H, W)``, region label map (int16) and its description.

    The road, when present, gets the label ``k`` (after the ``k`` Voronoi cells).
    """
    k = draws.integer(*regions)
    labels, cells = _voronoi(size, k, draws)
    desc: dict = {"kind": "voronoi", "cells": cells, "road": None}
    means = [cell["mean_db"] for cell in cells]
    if road:
        strip, desc["road"] = _road(size, draws)
        labels = torch.where(strip, k, labels)
        means.append(desc["road"]["mean_db"])
    table = torch.tensor(means, device=labels.device, dtype=torch.float32)
    return torch.pow(10.0, table[labels] / 10.0), labels.to(torch.int16), desc


def edge_pixels(labels: Tensor) -> Tensor:
    """``(m, 2)`` row/col indices of pixels whose right or lower neighbour has another label."""
    edge = torch.zeros(labels.shape, dtype=torch.bool, device=labels.device)
    edge[:, :-1] |= labels[:, :-1] != labels[:, 1:]
    edge[:-1, :] |= labels[:-1, :] != labels[1:, :]
    return torch.nonzero(edge)
