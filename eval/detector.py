"""A detector as the evaluator sees it: a callable on a batch of images, its options and what
it declares about its output.

Any callable ``fn(images, **options)`` on a batch ``(B, C, H, W)`` that returns a
:class:`~torchsar.cfar.Detection` (a statistic with its threshold: its objects come from
the shared discrimination stage) or :class:`~torchsar.objects.Objects` (its own instances:
masks, boxes or points with scores) is a detector: a function, a ``torch.nn.Module``, an
instance of a class with ``__call__``. A callable that also takes ``meta`` receives the
batch's per-image metadata (name, pixel spacing, dataset index) as ``meta=[dict, ...]``.

:class:`Detector` wraps it with a row name, the options, the operating threshold of the
scores it returns (``threshold``; ``None`` declares none), whether its own instances
are scored (``instances="auto"``) or its statistic always goes through the discrimination
stage (``"discriminate"``, for like-for-like comparisons), and the scale its objects'
scores are written on (``scale``): ``"auto"`` keeps a Detection's own statistic (a
probability stays a probability; the operating threshold is its single design threshold)
and falls back to ``statistic / threshold`` (operating threshold 1) only where the
threshold varies over a batch; ``"ratio"`` always uses the latter (for a detector whose
single threshold changes from batch to batch). A detector resolved from a
name or an import path (:func:`torchsar_eval.registry.load`) remembers it (``ref``) and
travels to worker processes by that reference, rebuilt there.
"""

from __future__ import annotations

import copy
import inspect
import io
import math
import pickle
import types
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import torch
from torch import Tensor

from torchsar.catalog import builtin_specs
from torchsar.detection import Detection
from torchsar.objects import Objects
from torchsar_eval.errors import EvalError

__all__ = [
    "HARNESS_OPTIONS",
    "INSTANCES",
    "SCALES",
    "Detector",
    "as_detector",
    "check_options",
    "check_portable",
    "split_options",
    "use_loader",
]

INSTANCES = ("auto", "discriminate")
SCALES = ("auto", "ratio")
HARNESS_OPTIONS = ("threshold", "instances", "scale")
"""Options the evaluator reads itself (unless the callable takes them too): the operating
threshold of the returned scores, the instance policy and the score scale."""


def _named(fn: Callable) -> list[str] | None:
    """The named parameters of a detector callable (a module's ``forward``)."""
    target = fn.forward if isinstance(fn, torch.nn.Module) else fn
    try:
        return list(inspect.signature(target).parameters)
    except (TypeError, ValueError):
        return None


def _keywords(fn: Callable) -> list[str] | None:
    """The keyword options of a detector callable (after the images), ``None`` if it takes
    ``**kwargs`` or has no inspectable signature."""
    target = fn.forward if isinstance(fn, torch.nn.Module) else fn
    try:
        params = list(inspect.signature(target).parameters.values())[1:]
    except (TypeError, ValueError):
        return None
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    return [p.name for p in params if p.kind is not inspect.Parameter.POSITIONAL_ONLY]


def check_options(fn: Callable, options: Mapping[str, Any], what: str) -> None:
    """Every key of ``options`` must be a keyword option of ``fn`` (unless it takes
    ``**kwargs``, which then checks them itself).

    Examples:
        >>> check_options(lambda x, guard=2: x, {"gaurd": 3}, "detector ca")
        Traceback (most recent call last):
        ...
        torchsar_eval.errors.EvalError: detector ca has no option 'gaurd'; valid: guard
    """
    valid = _keywords(fn)
    unknown = [] if valid is None else [k for k in options if k not in valid]
    if unknown:
        raise EvalError(f"{what} has no option {unknown[0]!r}; valid: {', '.join(valid or [])}")


def split_options(fn: Callable, options: Mapping[str, Any]) -> tuple[dict, dict]:
    """``(passed, harness)``: the options for the callable, and the harness settings among
    them (``threshold``, ``instances``, ``scale``; passed on too when the callable takes
    them)."""
    harness = {k: options[k] for k in HARNESS_OPTIONS if k in options}
    named = _keywords(fn) or []
    passed = {k: v for k, v in options.items() if k not in HARNESS_OPTIONS or k in named}
    return passed, harness


def _check_threshold(value: object, name: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
        raise EvalError(f"detector {name}: threshold must be a number or None, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Detector:
    """A detector of a run (see the module docstring).

    Attributes:
        name: the detector's row in the tables.
        fn: the callable ``fn(images, **call_options) -> Detection | Objects``.
        options: its options as recorded in ``config.json`` (and passed to each call
            unless the detector was built from them: see ``call_options``).
        threshold: operating threshold of the scores of returned :class:`Objects`
            (overrides theirs; ``None`` keeps theirs).
        instances: ``"auto"`` (score the detector's own instances when it returns them)
            or ``"discriminate"`` (always the shared discrimination stage).
        ref: import reference it was resolved from (a built-in or entry-point name, or
            ``module:attribute``); worker processes rebuild it from this.
        call_options: options passed to every call (default: ``options``).
    """

    name: str
    fn: Callable[..., Detection | Objects]
    options: Mapping[str, Any] = field(default_factory=dict)
    threshold: float | None = None
    instances: str = "auto"
    ref: str | None = None
    call_options: Mapping[str, Any] | None = None
    scale: str = "auto"

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or "," in self.name:
            raise EvalError(
                f"a detector name must be a non-empty string without commas, got {self.name!r}"
            )
        if not callable(self.fn):
            raise EvalError(f"detector {self.name}: {self.fn!r} is not callable")
        if self.instances not in INSTANCES:
            raise EvalError(
                f"detector {self.name}: instances must be one of "
                f"{', '.join(INSTANCES)}, got {self.instances!r}"
            )
        if self.scale not in SCALES:
            raise EvalError(
                f"detector {self.name}: scale must be one of "
                f"{', '.join(SCALES)}, got {self.scale!r}"
            )
        object.__setattr__(self, "threshold", _check_threshold(self.threshold, self.name))

    @property
    def params(self) -> Mapping[str, Any]:
        """The options passed to each call."""
        return self.options if self.call_options is None else self.call_options

    def has_option(self, key: str) -> bool:
        """Whether ``key`` is an option of this detector: a harness setting, one of its
        recorded options, or a keyword of its callable (one taking ``**kwargs`` has only
        the first two)."""
        if key in HARNESS_OPTIONS or key in self.options:
            return True
        keywords = _keywords(self.fn)
        return keywords is not None and key in keywords

    def with_options(self, overrides: Mapping[str, Any]) -> Detector:
        """The detector with options overridden (checked against the callable's keywords);
        ``threshold`` and ``instances`` set the harness's settings and are passed on only
        if the callable takes them."""
        passed, harness = split_options(self.fn, overrides)
        if self.call_options is not None and passed:  # built from its options: rebuild
            if self.ref is None:
                raise EvalError(
                    f"detector {self.name} was built from its options: build it "
                    "again with the new ones"
                )
            return _loader()(
                self.ref,
                name=self.name,
                options={**self.options, **passed},
                **{
                    "threshold": self.threshold,
                    "instances": self.instances,
                    "scale": self.scale,
                    **harness,
                },
            )
        check_options(self.fn, passed, f"detector {self.name}")
        call = None if self.call_options is None else dict(self.call_options)
        return replace(self, options={**self.options, **passed}, call_options=call, **harness)

    @property
    def needs_images(self) -> bool:
        """Whether the detector reads the pixels (saved predictions need only the shape)."""
        return bool(getattr(self.fn, "needs_images", True))

    def wants_meta(self) -> bool:
        """Whether the callable names a ``meta`` parameter (the batch metadata)."""
        return "meta" in (_named(self.fn) or []) and "meta" not in self.params

    def __call__(self, images: Tensor, meta: list[dict] | None = None) -> Detection | Objects:
        """Run the detector on a batch (``meta``: per-image metadata, for detectors that
        take it). The detector gets its own copy of the images and metadata: one that
        writes into its input (``images.mul_(0)``) changes nothing for the detectors after
        it or for the scoring (callables marked ``reads_only`` get the batch itself)."""
        kwargs = dict(self.params)
        if meta is not None and self.wants_meta():
            kwargs["meta"] = copy.deepcopy(meta)  # its own: a detector cannot change another's
        given = images
        if not getattr(self.fn, "reads_only", False):  # its own copy to write into, if it will
            images = images.clone()
        try:
            with torch.no_grad():
                out = self.fn(images, **kwargs)
        except SystemExit as exc:  # not the run's to end: an error naming the detector
            raise EvalError(
                f"detector {self.name} called sys.exit({exc.code!r}); a detector "
                "returns its detections or raises an error"
            ) from None
        return self.check_output(out, given)

    def check_output(self, out: object, images: Tensor) -> Detection | Objects:
        """Refuse an output that is neither a Detection nor Objects of this batch."""
        b, c, h, w = images.shape
        if isinstance(out, Detection):
            if tuple(out.statistic.shape) != (b, c, h, w):
                got = tuple(out.statistic.shape)
                raise EvalError(
                    f"detector {self.name} returned a statistic of shape {got} "
                    f"for images {(b, c, h, w)}"
                )
            return out
        if isinstance(out, Objects):
            if out.planes != b * c or tuple(out.shape) != (h, w):
                raise EvalError(
                    f"detector {self.name} returned Objects of {out.planes} planes "
                    f"of {tuple(out.shape)} for images {(b, c, h, w)}: pass "
                    f"planes={b * c} and shape=({h}, {w})"
                )
            return out if self.threshold is None else out.with_threshold(self.threshold)
        raise EvalError(
            f"detector {self.name} returned {type(out).__name__}: a detector must "
            "return a torchsar Detection or torchsar.objects.Objects"
        )

    def describe(self) -> dict[str, Any]:
        """What ``config.json`` records of this detector."""
        out: dict[str, Any] = dict(self.options)
        if self.ref is not None and not _is_builtin(self.ref):
            out["_ref"] = self.ref
        if self.threshold is not None:
            out["_threshold"] = self.threshold
        if self.instances != "auto":
            out["_instances"] = self.instances
        if self.scale != "auto":
            out["_scale"] = self.scale
        return out

    def __reduce__(self):
        if self.ref is None:
            return (_rebuild, (self.__dict__,))
        args = {
            "name": self.name,
            "options": dict(self.options),
            "threshold": self.threshold,
            "instances": self.instances,
            "scale": self.scale,
        }
        return (_load_kw, (_loader(), self.ref, args))


def _rebuild(state: dict) -> Detector:
    return Detector(**state)


def _load_kw(load: Callable, ref: str, kwargs: dict) -> Detector:
    return load(ref, **kwargs)


def _is_builtin(ref: str) -> bool:
    return ref in {s.name for s in builtin_specs()}


_LOADER: list[Callable[..., Detector]] = []
"""The function that resolves a detector reference (:func:`torchsar_eval.registry.load`,
which registers itself with :func:`use_loader` on import: every detector with a ``ref``
was made by it, so it is there whenever one is rebuilt)."""


def use_loader(load: Callable[..., Detector]) -> None:
    """Register the function that builds a detector from its reference and options."""
    _LOADER[:] = [load]


def _loader() -> Callable[..., Detector]:
    if not _LOADER:
        raise EvalError("no detector registry is loaded (import torchsar_eval.registry)")
    return _LOADER[0]


def _default_name(obj: object) -> str:
    name = getattr(obj, "name", None)
    if isinstance(name, str) and name:
        return name
    if isinstance(obj, types.FunctionType | types.BuiltinFunctionType | type):
        return obj.__name__
    return type(obj).__name__


def as_detector(obj: object, name: str | None = None) -> Detector:
    """A :class:`Detector` from a detector object: a :class:`Detector` (kept, renamed if
    ``name``) or any callable, whose ``name``, ``threshold``, ``instances`` and ``scale``
    attributes are used when present.

    Examples:
        >>> as_detector(lambda x: None, name="mine").name
        'mine'
    """
    if isinstance(obj, Detector):
        return obj if name is None else replace(obj, name=name)
    if not callable(obj):
        raise EvalError(
            f"a detector must be callable (images -> Detection | Objects), got {type(obj).__name__}"
        )
    thr = getattr(obj, "threshold", None)
    inst = getattr(obj, "instances", "auto")
    scale = getattr(obj, "scale", "auto")
    return Detector(
        name or _default_name(obj),
        obj,
        threshold=thr if isinstance(thr, int | float) and not isinstance(thr, bool) else None,
        instances=inst if inst in INSTANCES else "auto",
        scale=scale if scale in SCALES else "auto",
    )


class _MainFinder(pickle.Pickler):
    """Pickles into nothing, noting functions and classes that live in ``__main__``."""

    def __init__(self) -> None:

        super().__init__(io.BytesIO(), protocol=pickle.HIGHEST_PROTOCOL)
        self.main: list[str] = []

    def reducer_override(self, obj: object):
        if isinstance(obj, types.FunctionType | type) and getattr(obj, "__module__", "") in (
            "__main__",
            "__mp_main__",
        ):
            self.main.append(getattr(obj, "__qualname__", repr(obj)))
        return NotImplemented


def _from_main(name: str, where: str) -> EvalError:
    return EvalError(
        f"detector {name} is defined in __main__ ({where}), which worker processes cannot "
        "import: move it into a module and pass its import path (module:name), or run with "
        "{opt:workers}1"
    )


def check_portable(detectors: list[Detector]) -> None:
    """Refuse, with one line each, detectors that worker processes could not rebuild: a
    callable defined in ``__main__`` (a script or notebook: a worker re-runs the script or
    cannot find it) or one that cannot be pickled (a lambda, a local function)."""
    for det in detectors:
        if det.ref is not None:
            if det.ref.partition(":")[0] in ("__main__", "__mp_main__"):
                raise _from_main(det.name, det.ref)
            continue
        finder = _MainFinder()
        try:
            finder.dump(det)
        except Exception as exc:
            if not finder.main:
                raise EvalError(
                    f"detector {det.name} cannot be sent to worker processes "
                    f"({type(exc).__name__}: {exc}): define it at the top level of a module "
                    "and pass its import path (module:name), or run with {opt:workers}1"
                ) from None
        if finder.main:
            raise _from_main(det.name, finder.main[0])
