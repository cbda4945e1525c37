"""Full-image overlays: chosen images drawn whole, each detector's detections at its reported
operating point over the ground truth (``--overlay N`` or ``--overlay NAME,NAME``).

The images are the reported split's first ``N`` (in dataset order) or the named ones. After
the run is scored, each chosen image goes through every detector again (a handful of
images: a few detector calls), its objects are matched to the ground truth under the run's
rule at the operating point the tables report (a calibrated or swept detector's chosen
threshold included), and the image is drawn on its own grey scale (dB, 2nd to 99.5th
percentile) with:

- green: targets found; orange, twice as thick: targets missed;
- cyan: detections that match a target; magenta: false alarms;
- yellow: don't-care regions.

Files: ``overlays/<dataset>/<detector>/<image>.png`` and their index ``overlays/overlays.csv``
(:data:`OVERLAY_COLUMNS`). Images larger than :data:`MAX_SIDE` are block-averaged down;
images of at most :data:`SMALL` pixels a side are drawn at twice their size. The report
shows a copy of at most :data:`REPORT_SIDE` pixels a side (``<image>-small.png``, drawn
afresh at that size, not resampled) linked to the full picture.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from torchsar.metrics.assign import match_batch
from torchsar.metrics.object_state import above
from torchsar.metrics.truth import GroundTruth
from torchsar.objects import Objects
from torchsar_eval.batches import Indexed, as_dict
from torchsar_eval.errors import EvalError
from torchsar_eval.names import file_slugs, slug
from torchsar_eval.runner import run_detectors
from torchsar_eval.scoring import batch_truth

__all__ = [
    "FALSE_ALARM",
    "FOUND",
    "HIT",
    "IGNORE",
    "MAX_SIDE",
    "MISSED",
    "OVERLAY_COLUMNS",
    "REPORT_SIDE",
    "SMALL",
    "Overlay",
    "collect_overlays",
    "overlay_indices",
    "parse_overlay",
    "render_overlay",
    "write_overlays",
]

MAX_SIDE = 2048
"""The largest side an overlay is drawn at (larger images are block-averaged down)."""
REPORT_SIDE = 512
"""The largest side of the copy the report embeds."""
SMALL = 512
"""Images of at most this many pixels a side are drawn at twice their size."""
MAX_OVERLAYS = 64
"""The most images one run draws (per dataset)."""
OVERLAY_COLUMNS = [
    "dataset",
    "detector",
    "image",
    "position",
    "targets",
    "found",
    "missed",
    "hits",
    "false_alarms",
    "threshold",
    "file",
    "small",
]
"""Columns of ``overlays/overlays.csv``."""

_GREYS = 64
FOUND, MISSED, HIT, FALSE_ALARM, IGNORE = range(_GREYS, _GREYS + 5)
"""Palette indices of the outlines (below them, 64 grey levels)."""
_PALETTE = [v for g in range(_GREYS) for v in (round(g * 255 / (_GREYS - 1)),) * 3] + [
    *(0, 230, 118),  # target found
    *(255, 140, 0),  # target missed
    *(0, 190, 255),  # detection matching a target
    *(255, 64, 255),  # false alarm
    *(255, 212, 0),  # don't-care region
]


def parse_overlay(value: object) -> int | tuple[str, ...] | None:
    """``--overlay``'s value: a count (``"3"``, ``3``) or image names (``"a.png,b.png"``, a
    list); ``None``/``0`` for none.

    Examples:
        >>> parse_overlay("3"), parse_overlay("a.png, b.png"), parse_overlay(None)
        (3, ('a.png', 'b.png'), None)
    """
    if value is None or value is False:
        return None
    if isinstance(value, bool):
        raise EvalError("{opt:overlay}True: give a number of images or their names")
    if isinstance(value, int):
        n = value
    elif isinstance(value, str) and value.strip().isdigit():
        n = int(value.strip())
    else:
        names = (
            [value]
            if isinstance(value, str)
            else list(value)
            if isinstance(value, Sequence)
            else None
        )
        if names is None or not all(isinstance(v, str) for v in names):
            raise EvalError(f"{{opt:overlay}}{value!r}: give a number of images or their names")
        parts = tuple(p.strip() for v in names for p in v.split(",") if p.strip())
        if not parts:
            raise EvalError("{opt:overlay} names no image")
        if len(parts) > MAX_OVERLAYS:
            raise EvalError(f"{{opt:overlay}} names {len(parts)} images, more than {MAX_OVERLAYS}")
        return parts
    if not 0 <= n <= MAX_OVERLAYS:
        raise EvalError(f"{{opt:overlay}}{n}: draw from 0 to {MAX_OVERLAYS} images")
    return n or None


def _name_of(ds, i: int) -> str:
    key = getattr(ds, "item_key", None)
    if key is not None:
        return str(key(i)["name"])
    return str(as_dict(ds[i])["meta"].get("name", i))


def overlay_indices(
    ds, spec: int | tuple[str, ...], reported: list[int], dataset: str
) -> list[int]:
    """The dataset indices to draw: the first ``spec`` of the ``reported`` split, or the
    images named (a name matches an image's name, its file name or its file stem).

    Raises:
        EvalError: a name that matches no image of the dataset (a few of its names given).
    """
    if isinstance(spec, int):
        return list(reported[:spec])
    names = [_name_of(ds, i) for i in range(len(ds))]
    lookup: dict[str, int] = {}
    for i, full in enumerate(names):
        base = full.replace("\\", "/").rsplit("/", 1)[-1]
        for k in (full, base, base.rsplit(".", 1)[0]):
            lookup.setdefault(k, i)
    out = []
    for want in spec:
        if want not in lookup:
            some = ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")
            raise EvalError(
                f"{{opt:overlay}}dataset {dataset} has no image {want!r} (its images: {some})"
            )
        if lookup[want] not in out:
            out.append(lookup[want])
    return out


@dataclass
class Overlay:
    """One image drawn for one detector: palette indices and what the picture shows."""

    dataset: str
    detector: str
    image: str
    position: int
    pixels: np.ndarray
    counts: dict
    threshold: float | None
    small: np.ndarray | None = None

    def row(self, file: str, small: str) -> list:
        c = self.counts
        thr = "" if self.threshold is None else self.threshold
        return [
            self.dataset,
            self.detector,
            self.image,
            self.position,
            c["targets"],
            c["found"],
            c["missed"],
            c["hits"],
            c["false_alarms"],
            thr,
            file,
            small,
        ]


def collect_overlays(
    name: str,
    ds,
    results: list,
    indices: list[int],
    scoring,
    *,
    batch_size: int = 1,
    preprocess=None,
    device=None,
    default_class: str = "target",
) -> list[Overlay]:
    """Every detector of ``results`` (merged results, each with its reported operating
    threshold) on the images ``indices`` of ``ds``, matched and drawn."""

    if not indices or not results:
        return []
    detectors = [r.detector for r in results]
    chosen = {r.detector.name: (r.calibrated, r.threshold) for r in results}
    out: list[Overlay] = []

    def draw(batch: dict, found: dict[str, Objects]) -> None:
        gt, info = batch_truth(batch, name, scoring.bootstrap_unit)
        image = None if batch.get("truth_only") else batch["image"]
        for det in detectors:
            obj = found[det.name]
            calibrated, thr = chosen[det.name]
            if calibrated and obj.threshold != thr:  # reported at a chosen threshold
                obj = obj.with_threshold(thr)
            thr = obj.threshold
            m = match_batch(obj, gt, scoring.matching)
            for p, facts in enumerate(info):
                pixels, counts = render_overlay(image, p, obj, gt, m.op)
                small = None
                if max(pixels.shape) > REPORT_SIDE:
                    small = render_overlay(image, p, obj, gt, m.op, max_side=REPORT_SIDE)[0]
                meta = batch["meta"][p // max(1, gt.planes // len(batch["meta"]))]
                out.append(
                    Overlay(
                        name,
                        det.name,
                        str(facts.key),
                        int(meta["index"]),
                        pixels,
                        counts,
                        thr,
                        small,
                    )
                )

    run_detectors(
        Indexed(ds, indices),
        detectors,
        batch_size=batch_size,
        preprocess=preprocess,
        scoring=scoring,
        name=name,
        progress=False,
        on_batch=draw,
        device=device,
        default_class=default_class,
    )
    return out


def _grey(image, p: int, planes: int, h: int, w: int, step: int) -> np.ndarray:
    """Plane ``p`` in grey levels (dB, the plane's 2nd to 99.5th percentile), block-averaged
    by ``step``; mid grey where the batch holds no samples."""
    hs, ws = -(-h // step), -(-w // step)
    if image is None or getattr(image, "numel", lambda: 0)() == 0:
        return np.full((hs, ws), _GREYS // 2, np.uint8)
    b = int(image.shape[0])
    per = max(1, planes // max(b, 1))
    x = image[p // per]
    x = x[p % per] if x.shape[0] == per else x.abs().mean(0)
    x = x.detach().cpu().numpy().astype(np.float64, copy=False)
    if step > 1:
        pad = np.pad(x, ((0, hs * step - h), (0, ws * step - w)), mode="edge")
        x = pad.reshape(hs, step, ws, step).mean(axis=(1, 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        db = 10 * np.log10(np.maximum(x, 1e-30))
    finite = db[np.isfinite(db)]
    if finite.size == 0:
        return np.full((hs, ws), _GREYS // 2, np.uint8)
    lo, hi = np.percentile(finite, [2, 99.5])
    if not hi > lo:
        return np.full((hs, ws), _GREYS // 2, np.uint8)
    g = np.clip((np.nan_to_num(db, nan=lo) - lo) / (hi - lo), 0, 1)
    return np.round(g * (_GREYS - 1)).astype(np.uint8)


class _Canvas:
    """Palette indices of one overlay and outline drawing on them (``f``: image pixels per
    canvas pixel in the block-averaged direction, ``u``: canvas pixels per image pixel)."""

    def __init__(self, grey: np.ndarray, step: int, up: int) -> None:
        self.step, self.up = step, up
        self.pixels = grey.repeat(up, 0).repeat(up, 1) if up > 1 else grey.copy()

    def _cells(self, flat: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
        r, c = np.divmod(flat, w)
        return r // self.step, c // self.step

    def outline(self, flat: np.ndarray, w: int, colour: int, width: int = 1) -> None:
        """The ``width``-pixel band around the pixels ``flat`` (indices into one plane)."""
        if flat.size == 0:
            return
        r, c = self._cells(flat, w)
        u = self.up
        r0, c0 = int(r.min()) * u, int(c.min()) * u
        r1, c1 = (int(r.max()) + 1) * u, (int(c.max()) + 1) * u
        pad = width
        local = np.zeros((r1 - r0 + 2 * pad, c1 - c0 + 2 * pad), bool)
        for dr in range(u):
            for dc in range(u):
                local[r * u + dr - r0 + pad, c * u + dc - c0 + pad] = True
        grown = local
        for _ in range(width):
            g = np.pad(grown, 1)
            hh, ww = grown.shape
            grown = np.logical_or.reduce(
                [g[i : i + hh, j : j + ww] for i in range(3) for j in range(3)]
            )
        ring = grown & ~local
        rr, cc = np.nonzero(ring)
        rr, cc = rr + r0 - pad, cc + c0 - pad
        H, W = self.pixels.shape
        ok = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
        self.pixels[rr[ok], cc[ok]] = colour

    def box(self, box, colour: int, width: int = 1) -> None:
        """A rectangle around box ``(r0, c0, r1, c1)`` (end-exclusive image pixels)."""
        H, W = self.pixels.shape
        s = self.up / self.step
        r0, c0 = math.floor(box[0] * s), math.floor(box[1] * s)
        r1, c1 = max(math.ceil(box[2] * s), r0 + 1), max(math.ceil(box[3] * s), c0 + 1)
        for k in range(1, width + 1):
            top, bot, lef, rig = r0 - k, r1 - 1 + k, c0 - k, c1 - 1 + k
            cs = slice(max(lef, 0), min(rig + 1, W))
            rs = slice(max(top, 0), min(bot + 1, H))
            for row in (top, bot):
                if 0 <= row < H:
                    self.pixels[row, cs] = colour
            for col in (lef, rig):
                if 0 <= col < W:
                    self.pixels[rs, col] = colour

    def point(self, rc, colour: int) -> None:
        """A small ring around point ``(row, col)``."""
        H, W = self.pixels.shape
        s = self.up / self.step
        r, c = rc[0] * s, rc[1] * s
        rad = 4
        t = np.linspace(0, 2 * np.pi, 48, endpoint=False)
        rr = np.round(r + rad * np.sin(t)).astype(int)
        cc = np.round(c + rad * np.cos(t)).astype(int)
        ok = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
        self.pixels[rr[ok], cc[ok]] = colour


def render_overlay(
    image, p: int, obj: Objects, gt: GroundTruth, op: np.ndarray, *, max_side: int = MAX_SIDE
) -> tuple[np.ndarray, dict]:
    """Palette indices of plane ``p`` with its ground truth and the detections at their
    operating point (``op``: each detection's matched target under the rule, ``-1`` a false
    alarm, ``-2`` ignored), and the counts drawn; at most ``max_side`` pixels a side."""
    h, w = gt.shape
    step = max(1, math.ceil(max(h, w) / max_side))
    up = 2 if max(h, w) <= min(SMALL, max_side // 2) else 1
    canvas = _Canvas(_grey(image, p, gt.planes, h, w, step), step, up)
    base = p * h * w
    for k in np.flatnonzero(gt.crowd.plane == p):
        canvas.outline(gt.region_pixels(int(k)) - base, w, IGNORE)
    at_op = above(obj.score, obj.threshold)
    mine = obj.plane == p
    found = np.zeros(len(gt), bool)
    found[op[at_op & (op >= 0)]] = True
    width = 2 * up
    for k in np.flatnonzero(gt.plane == p):
        colour, wd = (FOUND, up) if found[k] else (MISSED, width)
        if gt.has_mask[k] or gt.masks.of(int(k)).size:
            canvas.outline(gt.pixels_of(int(k)) - base, w, colour, wd)
        else:
            canvas.box(gt.box[k], colour, wd)
    shown = np.flatnonzero(mine & at_op & (op != -2))
    owner, flat = obj.pixel_lists() if obj.geometry == "mask" else (None, None)
    for d in shown:
        colour = HIT if op[d] >= 0 else FALSE_ALARM
        if obj.geometry == "mask":
            canvas.outline(flat[owner == d] - base, w, colour, up)
        elif obj.geometry == "box":
            canvas.box(obj.box[d], colour, up)
        else:
            canvas.point(obj.centroid[d], colour)
    targets = np.flatnonzero(gt.plane == p)
    counts = {
        "targets": int(targets.size),
        "found": int(found[targets].sum()),
        "missed": int((~found[targets]).sum()),
        "hits": int((op[shown] >= 0).sum()),
        "false_alarms": int((op[shown] == -1).sum()),
    }
    return canvas.pixels, counts


def _file_name(image: str) -> str:
    """A file-safe stem of an image name (its base name without the extension)."""
    base = image.replace("\\", "/").rsplit("/", 1)[-1]
    stem = base.rsplit(".", 1)[0] if "." in base[1:] else base
    return re.sub(r"[^A-Za-z0-9_-]+", "_", stem) or "image"


def _png(pixels: np.ndarray, path: Path) -> None:
    # Pillow only when a picture is written (workers never load it)
    from PIL import Image

    im = Image.fromarray(pixels, "P")
    im.putpalette(_PALETTE)
    im.save(path, compress_level=6)


def write_overlays(
    folder: Path, overlays: dict[str, list[Overlay]], labels: dict[str, str]
) -> list[str]:
    """The overlays as PNGs ``overlays/<dataset>/<detector>/<image>.png`` and their index
    ``overlays/overlays.csv``; returns ``["overlays/"]`` (``[]`` when there are none)."""

    rows = []
    for name, items in overlays.items():
        dets = file_slugs(list(dict.fromkeys(o.detector for o in items)), slug)
        files = file_slugs(list(dict.fromkeys(o.image for o in items)), _file_name)
        for o in items:
            sub = Path("overlays") / labels[name] / dets[o.detector]
            (folder / sub).mkdir(parents=True, exist_ok=True)
            rel = sub / f"{files[o.image]}.png"
            _png(o.pixels, folder / rel)
            small = rel
            if o.small is not None:
                small = sub / f"{files[o.image]}-small.png"
                _png(o.small, folder / small)
            rows.append(o.row(rel.as_posix(), small.as_posix()))
    if not rows:
        return []
    with open(folder / "overlays" / "overlays.csv", "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(OVERLAY_COLUMNS)
        out.writerows(rows)
    return ["overlays/"]
