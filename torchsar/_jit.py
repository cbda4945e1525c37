"""Whether the compiled CPU kernels (numba) are used.

Two CPU loops of torchsar are sequential by nature and dominated by Python overhead when
written with numpy: the region-growing CFAR's per-seed work (heap growth, rings, test) and
the OS-CFAR's sliding order statistic. Both have numba kernels
(:mod:`torchsar.region._kernels`, :mod:`torchsar.order_statistics._kernels`) that return
the same values bit for bit as the numpy/torch code, which stays as the fallback and as the
reference the tests compare against. So do the window CFARs' per-pixel rules and strip sums
(:mod:`torchsar.cfar._kernels`, :mod:`torchsar._windows_kernels`). The one-sweep kernels
of CA-CFAR without no-data and of the Lee, Kuan and enhanced Lee filters
(:mod:`torchsar._box_kernels`) sum each window directly instead of through integral
images: their float32 results are within an ulp or two of the torch code's (tested), and
closer to the exact sums.

The kernels are imported (and compiled, or loaded from numba's on-disk cache) on first use
only, so ``import torchsar`` does not import numba.

numba reuses a cached kernel while *its own* source file is unchanged, but a kernel that
calls a kernel of another module carries its own compiled copy of the callee, which that
check does not see (after an edit of ``torchsar/_moment_kernels.py`` the speckle filters
of ``torchsar/_box_kernels.py`` would go on running the old moments). So the first
compiled call of a process also compares the sources of every module of the package that
uses numba with a stamp kept beside the cache and, when any of them changed, removes the
package's cached kernels (:func:`refresh_cache`): they compile again on first use (``make
setup`` does it ahead). An installed package, whose sources never change, keeps its
cache. Set the environment variable
``TORCHSAR_NUMBA=0`` to never use them; tests switch them with :data:`ENABLED`.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import os
import warnings
from pathlib import Path

__all__ = ["ENABLED", "cache_dirs", "enabled", "for_tensor", "refresh_cache", "sources_stamp"]


def installed(module: str) -> bool:
    """Whether the optional package ``module`` is installed (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a broken or blocked install counts as absent
        return False


ENABLED: bool = os.environ.get("TORCHSAR_NUMBA", "1") != "0" and installed("numba")


_IMPORTS: bool | None = None


def _numba_imports() -> bool:
    """Whether ``import numba`` works (tried once, on the first compiled call): an installed
    numba that fails to import (a broken install, a local module shadowing one of its
    dependencies) counts as absent, with one warning, instead of failing the detector."""
    global _IMPORTS
    if _IMPORTS is None:
        try:
            import numba  # noqa: F401
        except Exception as exc:  # any failure of a third-party import: fall back
            warnings.warn(
                f"numba is installed but cannot be imported ({type(exc).__name__}: "
                f"{exc}); torchsar uses its numpy/torch code instead (the same results "
                "to within a float32 ulp or two, slower)",
                UserWarning,
                stacklevel=3,
            )
            _IMPORTS = False
        else:
            _IMPORTS = True
            with contextlib.suppress(OSError):  # a cache it cannot clean: numba's own checks
                refresh_cache()
    return _IMPORTS


def enabled() -> bool:
    """Whether the numba kernels are to be used (numba installed, importable and not
    switched off)."""
    return ENABLED and _numba_imports()


def for_tensor(t) -> bool:
    """Whether the numba kernels are to be used on the tensor ``t``: a float32 or float64
    CPU tensor that needs no gradient (the kernels compute values only), with
    :func:`enabled`. Other tensors (other devices and dtypes, autograd) take the torch code."""
    import torch

    return (
        t.device.type == "cpu"
        and t.dtype in (torch.float32, torch.float64)
        and not t.requires_grad
        and enabled()
    )


PACKAGE = Path(__file__).resolve().parent
STAMP_NAME = "numba-sources.stamp"


def _kernel_sources(package: Path) -> list[Path]:
    """The package's modules that use numba (their text names it), sorted."""
    out = []
    for path in sorted(package.rglob("*.py")):
        try:
            if b"numba" in path.read_bytes():
                out.append(path)
        except OSError:
            continue
    return out


def sources_stamp(package: Path = PACKAGE) -> str:
    """Path, modification time and size of every module of ``package`` that uses numba,
    one per line (what numba itself compares for a module's own kernels)."""
    lines = []
    for path in _kernel_sources(package):
        st = path.stat()
        lines.append(f"{path.relative_to(package)} {st.st_mtime_ns} {st.st_size}")
    return "\n".join(lines)


def cache_dirs(package: Path = PACKAGE, cache_dir: str | None = None) -> list[Path]:
    """Where numba caches the kernels of every folder of ``package``: ``__pycache__``
    beside the sources, or, with ``NUMBA_CACHE_DIR`` (``cache_dir``), numba's folder for
    that source folder in it (its last name and the SHA-1 of its absolute path)."""
    folders = sorted({p.parent for p in package.rglob("*.py")})
    if cache_dir:
        root = Path(cache_dir)
        return [
            root / f"{f.name}_{hashlib.sha1(str(f.resolve()).encode()).hexdigest()}"
            for f in folders
        ]
    return [f / "__pycache__" for f in folders]


def refresh_cache(package: Path = PACKAGE, cache_dir: str | None = None) -> bool:
    """Remove ``package``'s cached kernels if any of its numba modules changed since the
    last call (or none was made); returns whether it removed them and wrote the new stamp
    (False where the stamp cannot be written; a read-only install's sources never change,
    and there the caller ignores the error of removing a cache file)."""
    cache_dir = os.environ.get("NUMBA_CACHE_DIR") if cache_dir is None else cache_dir
    stamp_dir = Path(cache_dir) if cache_dir else package / "__pycache__"
    stamp = stamp_dir / f"{package.name}-{STAMP_NAME}"
    now = sources_stamp(package)
    try:
        if stamp.read_text() == now:
            return False
    except OSError:
        pass
    for folder in cache_dirs(package, cache_dir):
        for pattern in ("*.nbi", "*.nbc"):
            for f in folder.glob(pattern):
                f.unlink(missing_ok=True)  # another process may remove it first
    try:
        stamp_dir.mkdir(parents=True, exist_ok=True)
        tmp = stamp.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(now)
        tmp.replace(stamp)
    except OSError:
        return False
    return True
