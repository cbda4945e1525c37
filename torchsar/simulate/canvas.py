"""One simulated image under construction: background, targets, shadows, ground truth.

A :class:`Canvas` holds the clean background (mean clutter intensity per pixel) and collects
targets one by one: each paints its body (instance id and mean intensity) and its radar
shadow. :meth:`Canvas.finish` composes the clean reflectivity and the ground truth; the
speckled image is ``clean * clutter`` (see :mod:`torchsar.simulate.clutter`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch
from torch import Tensor
from torch.nn import functional as nnf

from torchsar.simulate.shapes import Box, RotatedRect, sweep_down

__all__ = ["Canvas", "Placed"]


@dataclass(frozen=True)
class Placed:
    """A target ready to paint: its rectangle, body raster in ``box`` and levels in dB."""

    kind: str
    rect: RotatedRect
    box: Box
    body: Tensor
    level_db: Tensor
    clutter_mean: float
    shadow_px: int
    shadow_gain: float


def _tight_box(box: Box, body: Tensor) -> Box:
    """Tight end-exclusive bounding box of the ``True`` pixels of ``body`` placed at ``box``."""
    rows = torch.nonzero(body.any(dim=1)).flatten()
    cols = torch.nonzero(body.any(dim=0)).flatten()
    r0, c0 = box[0], box[1]
    return (
        r0 + int(rows[0]),
        c0 + int(cols[0]),
        r0 + int(rows[-1]) + 1,
        c0 + int(cols[-1]) + 1,
    )


@dataclass
class Canvas:
    """Mutable per-image state; ``background`` is the clean clutter mean ``(H, W)``."""

    background: Tensor
    instances: Tensor = field(init=False)
    level: Tensor = field(init=False)
    shade: Tensor = field(init=False)
    keepout: Tensor = field(init=False)
    targets: list[dict] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        bg = self.background
        self.instances = torch.zeros(bg.shape, dtype=torch.int32, device=bg.device)
        self.level = torch.zeros_like(bg)
        self.shade = torch.ones_like(bg)
        self.keepout = torch.zeros(bg.shape, dtype=torch.bool, device=bg.device)

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.background.shape[0], self.background.shape[1]

    def is_free(self, box: Box, body: Tensor) -> bool:
        """True when ``body`` (raster in ``box``) touches no kept-out pixel."""
        r0, c0, r1, c1 = box
        return not bool((self.keepout[r0:r1, c0:c1] & body).any())

    def reserve(self, box: Box, body: Tensor, gap: int) -> None:
        """Keep out ``body`` dilated by ``gap`` pixels (Chebyshev) from later targets."""
        H, W = self.shape
        r0, c0, r1, c1 = box
        R0, C0, R1, C1 = max(0, r0 - gap), max(0, c0 - gap), min(H, r1 + gap), min(W, c1 + gap)
        pad = torch.zeros((R1 - R0, C1 - C0), dtype=torch.float32, device=body.device)
        pad[r0 - R0 : r1 - R0, c0 - C0 : c1 - C0] = body.float()
        k = 2 * gap + 1  # separable square dilation: rows, then columns
        grown = nnf.max_pool2d(pad[None, None], (k, 1), stride=1, padding=(gap, 0))
        grown = nnf.max_pool2d(grown, (1, k), stride=1, padding=(0, gap))[0, 0] > 0
        self.keepout[R0:R1, C0:C1] |= grown

    def paint(self, target: Placed) -> int:
        """Paint a target's body and shadow; return its instance id (1, 2, ...)."""
        ident = len(self.targets) + 1
        r0, c0, r1, c1 = target.box
        body = target.body
        self.instances[r0:r1, c0:c1][body] = ident
        gain = torch.pow(10.0, target.level_db / 10.0) * target.clutter_mean
        self.level[r0:r1, c0:c1][body] = gain[body]
        self._shadow(target)
        self.targets.append(_describe(target, _tight_box(target.box, body)))
        return ident

    def _shadow(self, target: Placed) -> None:
        """Darken the pixels up to ``shadow_px`` rows behind the body (far range)."""
        H = self.shape[0]
        r0, c0, r1, c1 = target.box
        R1 = min(H, r1 + target.shadow_px)
        ext = torch.zeros((R1 - r0, c1 - c0), dtype=torch.bool, device=target.body.device)
        ext[: r1 - r0] = target.body
        shadow = sweep_down(ext, target.shadow_px) & ~ext
        region = self.shade[r0:R1, c0:c1]
        region[shadow] = torch.clamp(region[shadow], max=target.shadow_gain)

    def finish(self) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Return ``clean``, ``mask``, ``instances``, ``ignore``, each ``(H, W)``."""
        mask = self.instances > 0
        clean = torch.where(mask, self.level, self.background * self.shade)
        ignore = (self.shade < 1) & ~mask
        return clean, mask, self.instances, ignore


def _describe(target: Placed, box: Box) -> dict:
    """Per-instance metadata (plain Python values). ``scr_db`` is the target's known
    signal-to-clutter ratio: its mean clean intensity over its pixels relative to the clutter
    mean at its centre, in dB (the speckle multiplies both by unit-mean noise)."""
    rect = target.rect
    gain = torch.pow(10.0, target.level_db[target.body].double() / 10.0)
    return {
        "box": box,
        "class": target.kind,
        "center_rc": (rect.row, rect.col),
        "length_px": rect.length,
        "width_px": rect.width,
        "heading_deg": math.degrees(rect.heading),
        "clutter_mean": target.clutter_mean,
        "peak_db": float(target.level_db[target.body].max()),
        "scr_db": float(10.0 * torch.log10(gain.mean())),
        "shadow_px": target.shadow_px,
        "shadow_gain": target.shadow_gain,
        "group": -1,
        "near_edge": False,
    }
