"""What a resumed run must match: the fingerprint of the interrupted run (its options and
each dataset's files), recorded as ``resume.json`` in its staging folder."""

from __future__ import annotations

import json
from pathlib import Path

from torchsar_eval.errors import EvalError

__all__ = ["check_resumable", "fingerprint"]


def fingerprint(plan, datasets: dict) -> dict:
    """Everything a saved shard depends on (a resumed run must match it exactly)."""
    cal = plan.calibration
    return json.loads(
        json.dumps(
            {
                "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
                "detectors": {d.name: d.describe() for d in plan.detectors},
                "despeckle": plan.despeckle,
                "scoring": plan.scoring.as_dict(),
                "shard_size": plan.execution.shard_size,
                "calibration": None if cal is None else cal.as_dict(),
                # shards saved without their COCO part cannot serve
                "export_coco": plan.export_coco,
                "manifests": {
                    n: d.manifest() for n, d in datasets.items() if hasattr(d, "manifest")
                },
                "predictions": {
                    d.name: [str(d.fn.path), d.fn.digest]
                    for d in plan.detectors
                    if getattr(d.fn, "digest", None) is not None
                },
            },
            default=str,
        )
    )


def check_resumable(path: Path, expected: dict) -> None:
    """Record the run's fingerprint, or check it against the one of the run being resumed
    (the options, and each dataset's files: names, sizes and modification times)."""
    if path.exists():
        saved = json.loads(path.read_text())
        for name, now in expected.get("manifests", {}).items():
            before = saved.get("manifests", {}).get(name)
            if before is not None and before != now:
                raise EvalError(
                    f"{{opt:resume}}: dataset {name} changed since the interrupted "
                    f"run ({_manifest_change(before, now)}); start over with "
                    "{opt:discard}"
                )
        for name, (path, now) in expected.get("predictions", {}).items():
            before = saved.get("predictions", {}).get(name)
            if before is None or before[1] != now:
                raise EvalError(
                    f"{{opt:resume}}: the predictions of {name} ({path}) are not "
                    "those of the interrupted run (the file was replaced or "
                    "changed); start over with {opt:discard}"
                )
        if saved != expected:
            raise EvalError(
                f"{{opt:resume}}: the options differ from those of the interrupted "
                f"run (see {path.name} in its folder)"
            )
        return
    path.write_text(json.dumps(expected, indent=2) + "\n")


def _manifest_change(before: dict, now: dict) -> str:
    """What changed in a dataset's manifest, in words."""
    if before.get("files") != now.get("files") or before.get("bytes") != now.get("bytes"):
        return (
            f"{before.get('files')} files of {before.get('bytes')} bytes then, "
            f"{now.get('files')} files of {now.get('bytes')} bytes now"
        )
    if before.get("sha256") != now.get("sha256"):
        return "files renamed or resized"
    if before.get("sha256_mtime") != now.get("sha256_mtime"):
        return "files modified"
    return "its description differs"
