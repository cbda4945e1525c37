"""A detector's worst cases, chosen while scoring: its highest-scoring false alarms and its
largest missed targets, each kept as a small crop of the image with the ground truth and the
detections around it; beside them, typical hits (true positives drawn at random: each hit's
rank is a hash of its image and position, so the sample does not depend on the order).

:class:`Gallery` is a mergeable state of bounded size: each kind keeps at most
:data:`GALLERY_CASES` cases, ranked by a total order (false alarms: score, highest first;
misses: target area in pixels, largest first; ties: the image's position in the dataset, its
name, then the position in the image), so merging shards keeps the global top cases whatever
the shard size, batch size or worker count. Both kinds are taken at the design operating
point, like ``per_image.csv``. :func:`write_gallery` renders the cases as PNGs in
``gallery/`` with a ``gallery/cases.csv`` index.
"""

from __future__ import annotations

import csv
import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from torchsar.metrics.assign import BatchMatch
from torchsar.metrics.matching import GroundTruth, Matching
from torchsar.metrics.object_state import ImageInfo, above
from torchsar.metrics.reasons import false_alarm_reasons, miss_reasons
from torchsar.objects import Objects
from torchsar_eval.names import file_slugs, slug

__all__ = [
    "CASE_COLUMNS",
    "CROP",
    "GALLERY_CASES",
    "Cases",
    "Gallery",
    "at_operating_point",
    "observed_facts",
    "render_case",
    "write_gallery",
]

GALLERY_CASES = 8
"""Worst cases kept per kind (false alarms, misses) and detector."""
HITS = 4
"""Typical hits kept per detector."""
CROP = 96
"""Side of a case's crop in samples, and the least image extent it shows in pixels (a larger
object is shown whole, resampled)."""
TRUTH, FOUND, FOCUS, IGNORE, OUTSIDE = 1, 2, 4, 8, 16
"""Bits of a crop's mask: ground truth, detections at the operating point, the case's own
object, don't-care pixels, outside the image."""
CASE_COLUMNS = [
    "dataset",
    "detector",
    "kind",
    "rank",
    "image",
    "row",
    "col",
    "score",
    "area",
    "class",
    "why",
    "file",
]
"""Columns of ``gallery/cases.csv``."""
_MAX_FACTS = 6


@dataclass
class Cases:
    """Up to ``size`` cases of one kind, best first.

    Attributes:
        kind: ``"false_alarm"``, ``"miss"`` or ``"hit"``.
        size: the most cases kept.
        keys: each case's rank key (smaller first; a total order).
        info: each case's facts: image name, centre row and column, score, area, class.
        image: float16 ``(n, CROP, CROP)`` the crop in dB (``10 log10`` of the intensity;
            NaN outside the image).
        masks: uint8 ``(n, CROP, CROP)`` bits ``TRUTH | FOUND | FOCUS | IGNORE | OUTSIDE``.
    """

    kind: str
    size: int = GALLERY_CASES
    keys: list = field(default_factory=list)
    info: list = field(default_factory=list)
    image: np.ndarray = field(default_factory=lambda: np.zeros((0, CROP, CROP), np.float16))
    masks: np.ndarray = field(default_factory=lambda: np.zeros((0, CROP, CROP), np.uint8))

    def __post_init__(self) -> None:
        self._pending: list[tuple[tuple, Callable[[], tuple]]] = []

    def __len__(self) -> int:
        return len(self.keys) + len(self._pending)

    def __getstate__(self) -> dict:
        """Saved (and pickled) with every pending case built."""
        self.settle()
        return {k: v for k, v in self.__dict__.items() if k != "_pending"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._pending = []

    def ranked_keys(self) -> list:
        """The keys of the kept cases, built or pending, best first."""
        return sorted(self.keys + [k for k, _ in self._pending])[: self.size]

    def settle(self) -> Cases:
        """Build the pending cases that still make the cut (see :meth:`offer`); returns
        ``self``."""
        cut = self.ranked_keys()[-1] if self._pending else None
        todo = [(k, make) for k, make in self._pending if k <= cut]
        self._pending = []
        if todo:
            info, image, masks = zip(*(make() for _, make in todo), strict=True)
            new = Cases(
                self.kind,
                self.size,
                [k for k, _ in todo],
                list(info),
                np.stack(image),
                np.stack(masks),
            )
            merged = self + new
            self.keys, self.info, self.image, self.masks = (
                merged.keys,
                merged.info,
                merged.image,
                merged.masks,
            )
        return self

    def __add__(self, other: Cases) -> Cases:
        """The best ``size`` cases of both (disjoint parts of a dataset)."""
        self.settle(), other.settle()
        keys = self.keys + other.keys
        order = sorted(range(len(keys)), key=keys.__getitem__)[: self.size]
        info = self.info + other.info
        image = np.concatenate([self.image, other.image])[order]
        masks = np.concatenate([self.masks, other.masks])[order]
        return Cases(
            self.kind, self.size, [keys[i] for i in order], [info[i] for i in order], image, masks
        )

    def offer(
        self,
        keys: list[tuple],
        make: Callable[[int], tuple[dict, np.ndarray, np.ndarray]],
        defer: bool = False,
    ) -> None:
        """Add the candidates ``keys`` that make the cut; ``make(j)`` builds candidate
        ``j``'s ``(info, image, masks)``, only for those kept. With ``defer`` a kept
        candidate is built when the cases are next merged, saved or read (:meth:`settle`),
        and only if it is still among the best then: while a shard is scored most early
        candidates are pushed out by later ones (``make`` must not depend on state that
        changes meanwhile)."""
        if not keys:
            return
        kept = sorted(range(len(keys)), key=keys.__getitem__)[: self.size]
        ranked = self.ranked_keys()
        if len(ranked) >= self.size:
            kept = [j for j in kept if keys[j] < ranked[-1]]
        if not kept:
            return
        self._pending += [(keys[j], partial(make, j)) for j in kept]
        cut = self.ranked_keys()[-1]
        self._pending = [(k, m) for k, m in self._pending if k <= cut]
        if not defer:
            self.settle()


def _facts(a: list, b: list) -> list:
    """The smallest distinct values of both (bounded; associative)."""
    return sorted({tuple(v) for v in a} | {tuple(v) for v in b})[:_MAX_FACTS]


@dataclass
class Gallery:
    """A detector's worst cases on a dataset (mergeable by ``+``), and what the images
    were: their distinct sizes and pixel spacings (a few at most)."""

    false_alarms: Cases = field(default_factory=lambda: Cases("false_alarm"))
    misses: Cases = field(default_factory=lambda: Cases("miss"))
    shapes: list = field(default_factory=list)
    spacings: list = field(default_factory=list)
    hits: Cases = field(default_factory=lambda: Cases("hit", HITS))

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        if "hits" not in state:  # a gallery saved before hits were kept
            self.hits = Cases("hit", HITS)

    def __add__(self, other: Gallery) -> Gallery:
        return Gallery(
            self.false_alarms + other.false_alarms,
            self.misses + other.misses,
            _facts(self.shapes, other.shapes),
            _facts(self.spacings, other.spacings),
            self.hits + other.hits,
        )

    @property
    def kinds(self) -> list[tuple[Cases, str]]:
        """Each kind of case with its file prefix."""
        return [(self.false_alarms, "fa"), (self.misses, "miss"), (self.hits, "hit")]

    def settle(self) -> Gallery:
        """Build the pending cases of every kind (:meth:`Cases.settle`); returns ``self``."""
        for cases, _ in self.kinds:
            cases.settle()
        return self

    def add(
        self,
        obj: Objects,
        gt: GroundTruth,
        info: list[ImageInfo],
        m: BatchMatch,
        image,
        rule: Matching | None = None,
        types: np.ndarray | None = None,
    ) -> None:
        """Offer one batch's false alarms and misses at the design operating point
        (``image``: the batch's ``(B, C, H, W)`` images; ``rule`` and ``types``, the matching
        rule and each detection's false-alarm type, say why each case is one)."""
        n = len(info)
        h, w = gt.shape
        self.shapes = _facts(self.shapes, [(h, w)] * bool(n))
        sp = gt.spacing if gt.spacing is not None else np.full((n, 2), np.nan)
        self.spacings = _facts(
            self.spacings, [tuple(map(float, s)) for s in sp if np.isfinite(s).all()]
        )
        at_op = at_operating_point(obj)
        fa = np.flatnonzero(at_op & (m.op == -1))
        found = np.zeros(len(gt), bool)
        found[m.op[at_op & (m.op >= 0)]] = True
        missed = np.flatnonzero(~found)
        planes = _Planes(image, gt, obj, at_op, info, _Why(m, obj, gt, rule, at_op, types))
        defer = _deferrable(image)
        score = np.nan_to_num(obj.score.astype(np.float64), nan=-np.inf)
        keys, idx = _keys(-score[fa], obj.plane[fa], obj.box[fa], info, self.false_alarms)
        self.false_alarms.offer(
            keys,
            _maker(planes, fa[idx], obj.box, score, obj.area, obj.classes, obj.plane, "det"),
            defer,
        )
        gt_score = np.where(found, -np.inf, m.gt_score)
        area = gt.area[missed].astype(np.float64)
        keys, idx = _keys(-area, gt.plane[missed], gt.box[missed], info, self.misses)
        self.misses.offer(
            keys,
            _maker(planes, missed[idx], gt.box, gt_score, gt.area, gt.classes, gt.plane, "gt"),
            defer,
        )
        hit = np.flatnonzero(at_op & (m.op >= 0))
        draw = _draws(obj.box[hit], obj.plane[hit], info)
        keys, idx = _keys(draw, obj.plane[hit], obj.box[hit], info, self.hits)
        self.hits.offer(
            keys,
            _maker(planes, hit[idx], obj.box, score, obj.area, obj.classes, obj.plane, "hit"),
            defer,
        )


DEFER_BYTES = 8 << 20
"""Cases of a batch whose images take at most this many bytes (on the CPU) are built only if
they are still among the best when the gallery is saved or merged (:meth:`Cases.offer`): the
gallery then holds on to at most a few such batches."""


@dataclass(frozen=True)
class _Why:
    """What a batch's cases need to say why each is one (:mod:`torchsar.metrics.reasons`)."""

    m: BatchMatch
    obj: Objects
    gt: GroundTruth
    rule: Matching | None
    at_op: np.ndarray
    types: np.ndarray | None

    def __call__(self, k: int, own: str) -> str:
        if own == "hit":
            iou = float(self.m.op_iou[k])
            return f"matched (IoU {iou:.2f})" if iou > 0 else "matched"
        if self.rule is None:
            return ""
        if own == "det":
            if self.types is None:
                return ""
            return false_alarm_reasons(
                self.types, self.m, self.obj, self.gt, self.rule, np.array([k])
            )[0]
        return miss_reasons(self.m, self.obj, self.gt, self.rule, self.at_op, np.array([k]))[0]


def _draws(box: np.ndarray, plane: np.ndarray, info: list[ImageInfo]) -> np.ndarray:
    """A uniform draw in [0, 1) per object from its image and box (a hash: the same object
    draws the same number in any shard, batch or order)."""
    out = np.empty(len(box))
    for j in range(len(box)):
        text = f"{info[int(plane[j])].key}|{','.join(f'{v:.3f}' for v in box[j])}"
        digest = hashlib.blake2b(text.encode(), digest_size=8).digest()
        out[j] = int.from_bytes(digest, "little") / 2**64
    return out


def _deferrable(image) -> bool:
    if image is None or not hasattr(image, "element_size"):
        return False
    return image.device.type == "cpu" and image.numel() * image.element_size() <= DEFER_BYTES


def _maker(planes: _Planes, which: np.ndarray, box, score, area, classes, plane, own: str):
    """``make(j)`` of :meth:`Cases.offer` for the candidates ``which`` (objects or targets)."""

    def make(j: int) -> tuple[dict, np.ndarray, np.ndarray]:
        k = which[j]
        return planes.case(k, box[k], float(score[k]), int(area[k]), _class(classes, k), plane, own)

    return make


def observed_facts(results: list) -> dict:
    """What the images of a dataset were (from its first detector's gallery): the distinct
    image sizes ``[[H, W], ...]`` and pixel spacings ``[[row, col], ...]`` in metres, a few at
    most (``config.json`` records them as ``observed``)."""
    gallery = next((r.gallery for r in results if getattr(r, "gallery", None) is not None), None)
    if gallery is None:
        return {}
    return {
        "image_size": [list(v) for v in gallery.shapes],
        "pixel_spacing": [list(v) for v in gallery.spacings],
    }


def at_operating_point(obj: Objects) -> np.ndarray:
    """Which objects count at the design operating point (scores above the objects'
    threshold, or every object when they declare none)."""
    return above(obj.score, obj.threshold)


def _class(classes, k: int) -> str:
    return "" if classes is None or classes[k] is None else str(classes[k])


def _keys(
    value: np.ndarray, plane: np.ndarray, box: np.ndarray, info: list[ImageInfo], cases: Cases
) -> tuple[list[tuple], np.ndarray]:
    """Rank keys ``(value, image order, image name, centre row, centre col, box)`` of the
    candidates that may make the cut (value within the batch's best ``size`` and not worse
    than the worst kept case), and their positions among the candidates."""
    if value.size == 0:
        return [], np.zeros(0, np.int64)
    n = min(cases.size, value.size)
    cut = np.partition(value, n - 1)[n - 1]
    ranked = cases.ranked_keys()
    if len(ranked) >= cases.size:
        cut = min(cut, ranked[-1][0])
    idx = np.flatnonzero(value <= cut)
    keys = []
    for j in idx:
        i = info[int(plane[j])]
        r0, c0, r1, c1 = (float(v) for v in box[j])
        order = -1 if i.order is None else int(i.order)
        keys.append(
            (float(value[j]), order, str(i.key), (r0 + r1) / 2, (c0 + c1) / 2, r0, c0, r1, c1)
        )
    return keys, idx


class _Planes:
    """Crops of one batch's planes."""

    def __init__(
        self, image, gt: GroundTruth, obj: Objects, at_op: np.ndarray, info, why: _Why
    ) -> None:
        self.image, self.gt, self.obj, self.at_op, self.info = image, gt, obj, at_op, info
        self.why = why
        self.channels = gt.planes // max(1, int(image.shape[0])) if image is not None else 1
        self._stretch: dict[int, tuple[float, float]] = {}

    def stretch(self, p: int, x: np.ndarray) -> tuple[float, float]:
        """Plane ``p``'s display range in dB: its 2nd and 99.5th percentiles (on a regular
        grid of about 2**14 samples), so that every crop of an image is drawn on one grey
        scale."""
        if p not in self._stretch:
            step = max(1, int(np.sqrt(x.size / (1 << 14))))
            with np.errstate(divide="ignore", invalid="ignore"):
                db = 10 * np.log10(np.maximum(x[::step, ::step], 1e-30))
            db = db[np.isfinite(db)]
            lo, hi = np.percentile(db, [2, 99.5]) if db.size else (np.nan, np.nan)
            self._stretch[p] = (float(lo), float(hi))
        return self._stretch[p]

    def _plane_image(self, p: int) -> np.ndarray | None:
        img = self.image
        if img is None or getattr(img, "numel", lambda: 0)() == 0:
            return None
        c = self.channels
        b, ch = divmod(p, c)
        x = img[b]
        x = x[ch] if x.shape[0] == c else x.abs().mean(0)
        return x.detach().cpu().numpy().astype(np.float64, copy=False)

    def case(self, k: int, box, score: float, area: int, cls: str, planes: np.ndarray, own: str):
        """``(info, image, masks)`` of the case of object or instance ``k`` (``own``:
        ``"det"`` or ``"gt"``; ``planes``: the plane of each)."""
        k = int(k)
        p = int(planes[k])
        h, w = self.gt.ids.shape[-2:]
        r0, c0, r1, c1 = (float(v) for v in box)
        cr, cc = (r0 + r1) / 2, (c0 + c1) / 2
        side = max(CROP, math.ceil(1.25 * max(r1 - r0, c1 - c0)) + 8)
        step = side / CROP
        rr = np.floor(cr - side / 2 + (np.arange(CROP) + 0.5) * step).astype(np.int64)
        cs = np.floor(cc - side / 2 + (np.arange(CROP) + 0.5) * step).astype(np.int64)
        inside = ((rr >= 0) & (rr < h))[:, None] & ((cs >= 0) & (cs < w))[None, :]
        ri, ci = np.clip(rr, 0, h - 1), np.clip(cs, 0, w - 1)
        masks = np.where(inside, 0, OUTSIDE).astype(np.uint8)
        truth = self.gt.ids[p][np.ix_(ri, ci)] > 0
        if self.gt.box_only[p]:
            for g in np.flatnonzero(self.gt.plane == p):
                truth |= _in_box(self.gt.box[g], rr, cs)
        masks |= np.where(truth, TRUTH, 0).astype(np.uint8)
        masks |= np.where(self.gt.ignore[p][np.ix_(ri, ci)], IGNORE, 0).astype(np.uint8)
        found = np.zeros((CROP, CROP), bool)
        for d in np.flatnonzero((self.obj.plane == p) & self.at_op):
            if _overlaps(self.obj.box[d], rr, cs):
                found |= self._object(d, rr, cs, ri, ci, step)
        masks |= np.where(found, FOUND, 0).astype(np.uint8)
        if own in ("det", "hit"):
            focus = self._object(k, rr, cs, ri, ci, step)
        elif self.gt.box_only[p]:
            focus = _in_box(box, rr, cs)
        else:
            focus = self.gt.ids[p][np.ix_(ri, ci)] == k + 1
        masks |= np.where(focus, FOCUS, 0).astype(np.uint8)
        masks[~inside] &= OUTSIDE
        x = self._plane_image(p)
        lo, hi = math.nan, math.nan
        if x is None:
            crop = np.full((CROP, CROP), np.nan)
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                crop = 10 * np.log10(np.maximum(x[np.ix_(ri, ci)], 1e-30))
            crop[~inside] = np.nan
            lo, hi = self.stretch(p, x)
        info = {
            "image": self.info[p].key,
            "row": round(cr, 1),
            "col": round(cc, 1),
            "score": score if math.isfinite(score) else None,
            "area": area,
            "class": cls,
            "why": self.why(k, own),
            "lo_db": lo,
            "hi_db": hi,
        }
        return info, crop.astype(np.float16), masks

    def _object(self, d: int, rr, cs, ri, ci, step: float) -> np.ndarray:
        """Detection ``d``'s pixels on the crop grid (a point: a small disc)."""
        obj = self.obj
        if obj.geometry == "point":
            r, c = obj.centroid[d]
            rad = max(1.5, 1.5 * step)
            return (rr[:, None] - r) ** 2 + (cs[None, :] - c) ** 2 <= rad**2
        if obj.geometry == "box":
            return _in_box(obj.box[d], rr, cs)
        return obj.mask_of(int(d))[np.ix_(ri, ci)]


def _in_box(box, rr: np.ndarray, cs: np.ndarray) -> np.ndarray:
    r0, c0, r1, c1 = (float(v) for v in box)
    return ((rr >= math.floor(r0)) & (rr < max(math.ceil(r1), math.floor(r0) + 1)))[:, None] & (
        (cs >= math.floor(c0)) & (cs < max(math.ceil(c1), math.floor(c0) + 1))
    )[None, :]


def _overlaps(box, rr: np.ndarray, cs: np.ndarray) -> bool:
    r0, c0, r1, c1 = (float(v) for v in box)
    return r1 >= rr[0] and r0 <= rr[-1] + 1 and c1 >= cs[0] and c0 <= cs[-1] + 1


_GREYS = 64  # grey levels (plenty for speckle; fewer bytes per PNG)
_OUTSIDE, _TRUTH, _FOUND, _IGNORE = 64, 65, 66, 67
_PALETTE = [v for g in range(_GREYS) for v in (round(g * 255 / (_GREYS - 1)),) * 3] + [
    *(223, 228, 234),  # outside the image
    *(0, 230, 118),  # ground truth outline
    *(255, 64, 255),  # detection outline
    *(255, 212, 0),  # don't-care outline
]
SCALE = 2
"""Crops are drawn at twice their size (outlines fall between samples)."""


def _dilate(mask: np.ndarray) -> np.ndarray:
    p = np.pad(mask, 1)
    h, w = mask.shape
    return np.logical_or.reduce([p[i : i + h, j : j + w] for i in range(3) for j in range(3)])


def _ring(mask: np.ndarray, width: int) -> np.ndarray:
    """The ``width``-pixel band just outside ``mask``."""
    grown = mask
    for _ in range(width):
        grown = _dilate(grown)
    return grown & ~mask


def render_case(
    image: np.ndarray,
    masks: np.ndarray,
    kind: str = "false_alarm",
    stretch: tuple[float, float] | None = None,
) -> np.ndarray:
    """Palette indices ``(SCALE * side, SCALE * side)`` of one case: the crop in grey
    (``stretch``: the image's dB range, else the 2nd to 99.5th percentile of the crop's),
    outlines of the don't-care pixels (yellow), the ground truth (green) and the detections
    at the operating point (magenta), the case's own object outlined twice as thick in its
    own colour, drawn last (a missed target under a detection stays green)."""
    img = np.asarray(image, np.float64)
    finite = np.isfinite(img)
    grey = np.full(img.shape, _GREYS // 2, np.uint8)
    if finite.any():
        lo, hi = np.percentile(img[finite], [2, 99.5])
        if stretch is not None and np.isfinite(stretch).all() and stretch[1] > stretch[0]:
            lo, hi = stretch
        if hi > lo:
            grey = np.clip((img - lo) / (hi - lo), 0, 1)
            grey = np.round(np.nan_to_num(grey) * (_GREYS - 1)).astype(np.uint8)
    big = grey.repeat(SCALE, axis=0).repeat(SCALE, axis=1)
    bits = np.asarray(masks).repeat(SCALE, axis=0).repeat(SCALE, axis=1)
    big[(bits & OUTSIDE) > 0] = _OUTSIDE
    for bit, colour in ((IGNORE, _IGNORE), (TRUTH, _TRUTH), (FOUND, _FOUND)):
        big[_ring((bits & bit) > 0, 1)] = colour
    focus = (bits & FOCUS) > 0
    if focus.any():
        big[_ring(focus, 2)] = _TRUTH if kind == "miss" else _FOUND
    return big


def _png(indices: np.ndarray, path: Path) -> None:
    # Pillow only when a picture is written (workers never load it)
    from PIL import Image

    im = Image.fromarray(indices, "P")
    im.putpalette(_PALETTE)
    im.save(path, compress_level=6)  # (optimize's extra passes cost more than they save)


def write_gallery(folder: Path, results: dict, labels: dict[str, str]) -> list[str]:
    """Each detector's cases as PNGs ``gallery/<dataset>/<detector>/<kind>-NN.png`` and
    their index ``gallery/cases.csv`` (columns :data:`CASE_COLUMNS`); returns
    ``["gallery/"]``, or ``[]`` when no result holds a gallery."""

    rows = []
    for name, rs in results.items():
        dets = file_slugs([r.detector.name for r in rs], slug)
        for r in rs:
            gallery = getattr(r, "gallery", None)
            if gallery is None:
                continue
            for cases, short in gallery.kinds:
                cases.settle()
                sub = Path("gallery") / labels[name] / dets[r.detector.name]
                for rank, info in enumerate(cases.info, 1):
                    rel = sub / f"{short}-{rank:02d}.png"
                    (folder / sub).mkdir(parents=True, exist_ok=True)
                    stretch = (info.get("lo_db", math.nan), info.get("hi_db", math.nan))
                    _png(
                        render_case(
                            cases.image[rank - 1], cases.masks[rank - 1], cases.kind, stretch
                        ),
                        folder / rel,
                    )
                    rows.append(
                        [
                            name,
                            r.detector.name,
                            cases.kind,
                            rank,
                            info["image"],
                            info["row"],
                            info["col"],
                            info["score"],
                            info["area"],
                            info["class"],
                            info.get("why", ""),
                            rel.as_posix(),
                        ]
                    )
    if not rows and not any(getattr(r, "gallery", None) for rs in results.values() for r in rs):
        return []
    (folder / "gallery").mkdir(exist_ok=True)
    with open(folder / "gallery" / "cases.csv", "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(CASE_COLUMNS)
        out.writerows(rows)
    return ["gallery/"]
