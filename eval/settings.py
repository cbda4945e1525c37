"""The settings of a run that are not about scoring: how it executes (batches, shards,
workers, engine, device) and how its operating points are calibrated."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import torch

from torchsar_eval.calibrate import parse_target
from torchsar_eval.errors import EvalError
from torchsar_eval.sweep import check_sweep

__all__ = ["ENGINES", "Calibration", "Execution"]

ENGINES = ("local", "ray")


@dataclass(frozen=True)
class Execution:
    """How a run executes (none of it changes the tables).

    Attributes:
        batch_size: images per batch.
        shard_size: images per shard, the unit of work and of resume.
        workers: local worker processes (each with ``cores // workers`` torch threads);
            detectors must then be importable by name (see :func:`torchsar_eval.load`).
        engine: ``"local"`` or ``"ray"`` (needs Ray; the engine ships torchsar to the
            workers).
        address: Ray cluster address (default: a local Ray instance).
        skip_bad: skip the images that cannot be read or that a detector fails on (each
            named in the summary), and shards whose worker died twice; by default the
            first such error stops the run.
        max_bad: with ``skip_bad``, the largest share of a dataset's images that may be
            skipped (0 to 1); beyond it the run fails and publishes nothing. Default:
            any share short of all: a run that scored no image of a dataset always fails.
        progress: progress bars on stderr.
        device: where detectors run (``"cpu"``, ``"cuda"``, ``"cuda:1"``); batches move
            there and back for scoring, which stays on the CPU.
        overlap: each worker runs the detectors on its next batch while it scores this one
            (one more batch in memory; the same numbers either way).
    """

    batch_size: int = 16
    shard_size: int = 256
    workers: int = 1
    engine: str = "local"
    address: str | None = None
    skip_bad: bool = False
    progress: bool = True
    device: str | None = None
    max_bad: float | None = None
    overlap: bool = True

    def __post_init__(self) -> None:
        for name in ("batch_size", "shard_size", "workers"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise EvalError(f"{{opt:{name}}}{v!r}: must be an integer >= 1")
        if not isinstance(self.overlap, bool):
            raise EvalError(f"{{opt:overlap}}{self.overlap!r}: must be True or False")
        if self.max_bad is not None and not (
            isinstance(self.max_bad, int | float) and 0 <= self.max_bad <= 1
        ):
            raise EvalError(f"{{opt:max_bad}}{self.max_bad!r}: must be a share from 0 to 1")
        if self.engine not in ENGINES:
            raise EvalError(f"{{opt:engine}}{self.engine!r}: expected one of {', '.join(ENGINES)}")
        if self.device is not None:
            # the library only when a device is named: the command parsers import this module
            from torchsar._checks import check_device
            from torchsar.errors import TorchSARError

            try:
                torch.device(self.device)
            except (RuntimeError, TypeError):
                raise EvalError(
                    f"{{opt:device}}{self.device!r} is not a device (cpu, cuda, cuda:N)"
                ) from None
            if torch.device(self.device).type == "meta":
                raise EvalError(
                    f"{{opt:device}}{self.device!r} holds no data (shapes only): use cpu or cuda"
                )
            try:
                check_device(self.device, "device")
            except TorchSARError:
                raise EvalError(
                    f"{{opt:device}}{self.device!r} is not available on this machine: use cpu"
                ) from None


@dataclass(frozen=True)
class Calibration:
    """Choose each detector's operating point on a hashed ``fraction`` of the images for
    ``target`` (``"fa=L"``: at most L false alarms per image; ``"f1"``: best F1) and report
    on the disjoint rest."""

    target: str
    fraction: float = 0.3
    sweep: Mapping[str, Sequence] | None = None
    """Options to search on the calibration split (``{"pfa": [1e-3, 1e-4], "train": [4, 8]}``):
    each detector that has some of them keeps the setting that best meets ``target`` there,
    at its design operating point (see :mod:`torchsar_eval.sweep`); the others have their
    operating threshold chosen as without a sweep."""

    def __post_init__(self) -> None:
        parse_target(self.target)
        if not 0 < self.fraction < 1:
            raise EvalError(f"{{opt:calibration_fraction}}{self.fraction}: must be in (0, 1)")
        if self.sweep is not None:
            object.__setattr__(self, "sweep", check_sweep(self.sweep))

    def as_dict(self) -> dict:
        """The record of ``config.json``."""
        out = {"target": self.target, "fraction": self.fraction}
        return {**out, "sweep": self.sweep} if self.sweep is not None else out
