"""Dataset names: ``scheme:PATH?key=value&key=value`` parsed into typed options."""

from __future__ import annotations

from dataclasses import dataclass

from torchsar.io import SAMPLE_TYPES
from torchsar_eval.errors import EvalError

__all__ = ["DEFAULT_MAX_PIXELS", "DatasetSpec", "parse_spacing", "parse_spec"]

DEFAULT_MAX_PIXELS = 4096 * 4096
"""The evaluator's default limit on one image's ``H * W`` (``max_pixels=N`` raises it).

Scoring one image with every default detector peaks at 150 to 200 bytes per pixel on top
of about 0.5 GB for the process (peak resident memory of ``torchsar-eval run`` on one
speckled 8-bit folder image: 0.52 GB at 64 x 64, 0.55 GB at 1000 x 1000, 1.15 GB at
2000 x 2000, 1.85 GB at 3000 x 3000), so a 4096 x 4096 image takes 3 to 4 GB and two
workers fit a 2-core, 24 GB machine with room to spare; the former limit of 100,000,000
pixels meant 15 to 20 GB for one image. Checked from the file header, before anything
is decoded."""


@dataclass(frozen=True)
class DatasetSpec:
    """A parsed dataset name: its scheme, path and raw ``key=value`` options."""

    scheme: str
    path: str
    options: dict[str, str]

    def check_keys(self, allowed: tuple[str, ...]) -> None:
        """Refuse options this scheme does not know, listing the ones it does."""
        unknown = sorted(set(self.options) - set(allowed))
        if unknown:
            raise EvalError(
                f"unknown {self.scheme} option(s) {unknown}; allowed: {', '.join(allowed)}"
            )

    def choice(self, key: str, allowed: tuple[str, ...], default: str | None) -> str | None:
        """Option ``key`` checked against ``allowed`` (``default`` when absent)."""
        value = self.options.get(key, default)
        if value is not None and value not in allowed:
            raise EvalError(f"{self.scheme} option {key}={value!r}; allowed: {', '.join(allowed)}")
        return value

    def sample_type(self, default: str | None) -> str | None:
        """The declared ``type`` (one of the sample types) or the scheme's default."""
        return self.choice("type", SAMPLE_TYPES, default)

    def spacing(self, default: tuple[float, float] | None = None) -> tuple[float, float] | None:
        """``spacing=0.3`` or ``spacing=0.3,0.5`` (row, column metres), else ``default``."""
        raw = self.options.get("spacing")
        return default if raw is None else parse_spacing(raw)

    def max_pixels(self) -> int:
        """The ``max_pixels`` option (default :data:`DEFAULT_MAX_PIXELS`)."""
        return self.positive_int("max_pixels", DEFAULT_MAX_PIXELS)

    def positive_int(self, key: str, default: int) -> int:
        """A positive integer option (e.g. ``max_pixels``)."""
        raw = self.options.get(key)
        try:
            value = default if raw is None else int(raw)
        except ValueError:
            raise EvalError(f"{self.scheme} option {key}={raw!r} must be an integer") from None
        if value <= 0:
            raise EvalError(f"{self.scheme} option {key} must be > 0, got {value}")
        return value


def parse_spacing(raw: str) -> tuple[float, float]:
    """``"0.3"`` -> ``(0.3, 0.3)``; ``"0.3,0.5"`` -> ``(0.3, 0.5)`` (positive metres)."""
    try:
        parts = tuple(float(v) for v in raw.split(","))
    except ValueError:
        parts = ()
    if len(parts) not in (1, 2) or not all(0 < p < float("inf") for p in parts):
        raise EvalError(f"spacing={raw!r}: expected metres as ROW or ROW,COL (positive numbers)")
    return (parts[0], parts[-1])


def parse_spec(spec: str) -> DatasetSpec:
    """Split ``scheme:PATH?k=v&k=v``; a bare option without ``=`` is an error."""
    scheme, _, rest = spec.partition(":")
    path, _, query = rest.partition("?")
    options = {}
    for kv in filter(None, query.split("&")):
        key, sep, value = kv.partition("=")
        if not sep or not key:
            raise EvalError(f"dataset option {kv!r} in {spec!r} must be key=value")
        options[key] = value
    if not path:
        raise EvalError(f"dataset {spec!r} needs a path after '{scheme}:'")
    return DatasetSpec(scheme, path, options)
