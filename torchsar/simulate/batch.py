"""The simulated batch: speckled image, clean reflectivity and ground truth, and what every
simulator shares (batch options, the speckled image of a painted canvas, the batch loop)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import check_int, check_positive
from torchsar.seeding import check_device, check_seed, image_seed, make_generator
from torchsar.simulate.canvas import Canvas
from torchsar.simulate.clutter import ClutterSpec, clutter_spec, sample_clutter

__all__ = ["BatchOptions", "SimBatch", "build_batch", "speckle_canvas"]

_FIELDS = ("image", "clean", "mask", "instances", "ignore")


@dataclass(frozen=True)
class SimBatch:
    """A batch of simulated SAR intensity images with ground truth.

    Attributes:
        image: ``(n, 1, H, W)`` float32 speckled intensity, ``clean * clutter``.
        clean: ``(n, 1, H, W)`` float32 noise-free mean intensity (reflectivity); the clutter
            texture of K/G0 models is part of the random clutter, not of ``clean``.
        mask: ``(n, 1, H, W)`` bool target pixels (``instances > 0``).
        instances: ``(n, 1, H, W)`` int32 instance ids, 0 = background, 1..k per image.
        ignore: ``(n, 1, H, W)`` bool don't-care pixels (radar shadow), disjoint from ``mask``.
        meta: one dict per image: ``boxes`` (``(r0, c0, r1, c1)`` end-exclusive, one per
            instance in id order), ``classes``, ``targets`` (per-instance details),
            ``clutter`` (model, looks, shape_param), ``seed`` (the per-image seed), ``index``,
            ``batch_seed``, ``pixel_m``, ``regions`` (description of the background),
            ``shadow`` (``"ignore"``: the ignore pixels are the targets' radar shadows).
            Each ``targets`` entry holds ``scr_db``, the target's known signal-to-clutter
            ratio (mean clean intensity over its pixels / clutter mean at its centre, dB).

    Examples:
        >>> from torchsar.simulate import chips
        >>> b = chips(2, size=64, length_px=(16, 24))
        >>> len(b), b[1]["image"].shape, b[1]["meta"]["classes"]
        (2, torch.Size([1, 64, 64]), ['vehicle'])
    """

    image: Tensor
    clean: Tensor
    mask: Tensor
    instances: Tensor
    ignore: Tensor
    meta: list[dict]

    def __len__(self) -> int:
        return int(self.image.shape[0])

    def __getitem__(self, i: int) -> dict:
        """Image ``i`` as a dict of ``(1, H, W)`` tensors plus its ``meta``."""
        out: dict = {name: getattr(self, name)[i] for name in _FIELDS}
        out["meta"] = self.meta[i]
        return out

    def to(self, device: torch.device | str) -> SimBatch:
        """A copy of the batch with every tensor on ``device``."""
        moved = {name: getattr(self, name).to(device) for name in _FIELDS}
        return SimBatch(**moved, meta=self.meta)

    @staticmethod
    def stack(parts: list[dict], size: tuple[int, int], device: torch.device) -> SimBatch:
        """Stack per-image dicts of ``(H, W)`` tensors (and ``meta``) into a batch."""
        dtypes = {
            "image": torch.float32,
            "clean": torch.float32,
            "mask": torch.bool,
            "instances": torch.int32,
            "ignore": torch.bool,
        }
        if not parts:
            empty = {
                k: torch.zeros((0, 1, *size), dtype=d, device=device) for k, d in dtypes.items()
            }
            return SimBatch(**empty, meta=[])
        fields = {k: torch.stack([p[k] for p in parts])[:, None].to(d) for k, d in dtypes.items()}
        return SimBatch(**fields, meta=[p["meta"] for p in parts])


@dataclass(frozen=True)
class BatchOptions:
    """The validated options every simulator takes: which images, clutter, pixel, device."""

    n: int
    seed: int
    start: int
    clutter: ClutterSpec
    pixel_m: float
    device: torch.device

    @staticmethod
    def check(
        n: object,
        seed: object,
        start: object,
        model: object,
        looks: object,
        shape_param: object,
        pixel_m: object,
        device: object,
    ) -> BatchOptions:
        """Validate the shared options, in this order (see :func:`~torchsar.simulate.chips`)."""
        return BatchOptions(
            check_int(n, "n", minimum=0),
            check_seed(seed),
            check_int(start, "start", minimum=0),
            clutter_spec(model, looks=looks, shape_param=shape_param),
            check_positive(pixel_m, "pixel_m"),
            check_device(device),
        )


def speckle_canvas(
    canvas: Canvas, gen: torch.Generator, opts: BatchOptions, **meta: object
) -> dict:
    """The image of a painted canvas: ``clean * clutter`` drawn from ``gen``, with its ground
    truth and ``meta`` (boxes, classes, targets, clutter, pixel_m, then ``meta``)."""
    clean, mask, instances, ignore = canvas.finish()
    image = clean * sample_clutter(opts.clutter, tuple(clean.shape), gen, torch.float32)
    info = {
        "boxes": [t["box"] for t in canvas.targets],
        "classes": [t["class"] for t in canvas.targets],
        "targets": canvas.targets,
        "clutter": opts.clutter.as_dict(),
        "pixel_m": opts.pixel_m,
        "shadow": "ignore",
        **meta,
    }
    fields = (image, clean, mask, instances, ignore)
    return {**dict(zip(_FIELDS, fields, strict=True)), "meta": info}


def build_batch(
    opts: BatchOptions, size: tuple[int, int], render: Callable[[torch.Generator], dict]
) -> SimBatch:
    """Render images ``start .. start + n - 1``, each from its own seeded generator.

    ``render(generator)`` returns a dict of ``(H, W)`` tensors and a ``meta`` dict; the seed
    bookkeeping (``index``, ``seed``, ``batch_seed``) is added here.
    """
    parts = []
    for index in range(opts.start, opts.start + opts.n):
        s = image_seed(opts.seed, index)
        part = render(make_generator(s, opts.device))
        part["meta"] = {"index": index, "seed": s, "batch_seed": opts.seed, **part["meta"]}
        parts.append(part)
    return SimBatch.stack(parts, size, opts.device)
