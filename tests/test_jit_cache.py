"""numba's cache of the kernels is cleared when a module that uses numba changes: a kernel
carries compiled copies of the kernels it calls from other modules, which numba's own
check (the kernel's own source file) does not see."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from torchsar import _jit


def _package(tmp_path: Path) -> Path:
    pkg = tmp_path / "pkg"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    (pkg / "__pycache__").mkdir()
    (pkg / "kernels.py").write_text("from numba import njit\n")
    (pkg / "sub" / "more.py").write_text("import numba\n")
    (pkg / "plain.py").write_text("x = 1\n")
    return pkg


def _cached(pkg: Path) -> list[str]:
    return sorted(p.name for p in pkg.rglob("*") if p.suffix in (".nbi", ".nbc", ".pyc"))


def _put(pkg: Path) -> None:
    for folder in (pkg / "__pycache__", pkg / "sub" / "__pycache__"):
        for name in ("k.f-1.py311.nbi", "k.f-1.py311.1.nbc", "k.cpython-311.pyc"):
            (folder / name).write_text("")


def _touch(path: Path) -> None:
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))


def test_a_changed_kernel_module_clears_the_cache(tmp_path):
    pkg = _package(tmp_path)
    _put(pkg)
    assert _jit.refresh_cache(pkg, "") is True  # no stamp yet: cleared
    assert _cached(pkg) == ["k.cpython-311.pyc"] * 2  # bytecode kept
    _put(pkg)
    assert _jit.refresh_cache(pkg, "") is False  # unchanged: kept
    assert len(_cached(pkg)) == 6
    _touch(pkg / "plain.py")  # no numba there: kept
    assert _jit.refresh_cache(pkg, "") is False
    _touch(pkg / "sub" / "more.py")
    assert _jit.refresh_cache(pkg, "") is True
    assert _cached(pkg) == ["k.cpython-311.pyc"] * 2


def test_the_cache_folder_is_numbas_own(tmp_path):
    """With ``NUMBA_CACHE_DIR``, numba keeps a source folder's kernels in a folder named
    from its path; the stamp goes there too."""
    caching = pytest.importorskip("numba.core.caching")
    pkg = _package(tmp_path)
    root = tmp_path / "cache"
    dirs = _jit.cache_dirs(pkg, str(root))
    want = {
        root / caching._CacheLocator.get_suitable_cache_subpath(str(f))
        for f in (pkg / "kernels.py", pkg / "sub" / "more.py")
    }
    assert set(dirs) == want
    for d in dirs:
        d.mkdir(parents=True)
        (d / "k.f-1.py311.nbi").write_text("")
    assert _jit.refresh_cache(pkg, str(root)) is True
    assert not list(root.rglob("*.nbi")) and list(root.glob("*.stamp"))
    assert _jit.refresh_cache(pkg, str(root)) is False


def test_the_package_stamp_lists_its_kernel_modules():
    stamp = _jit.sources_stamp()
    names = {line.split(" ")[0] for line in stamp.splitlines()}
    assert {"_box_kernels.py", "_moment_kernels.py", "_block_sums.py"} <= names
    assert "errors.py" not in names
