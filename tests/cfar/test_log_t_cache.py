"""The log-t factors' on-disk cache: what it returns is what the computation gives, bit for
bit; a damaged, foreign or unwritable cache is a miss, never a wrong factor."""

from __future__ import annotations

import os

import pytest

from torchsar import _disk_cache
from torchsar.cfar import log_t


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache folder, and no factor kept in memory."""
    monkeypatch.setenv(_disk_cache.CACHE_ENV, str(tmp_path / "cache"))
    log_t.log_t_exact.cache_clear()
    yield tmp_path / "cache"
    log_t.log_t_exact.cache_clear()


def _files(folder) -> list:
    return sorted((folder / "log_t").glob("*.json")) if (folder / "log_t").exists() else []


def _no_compute(monkeypatch):
    def fail(*_):
        raise AssertionError("computed although cached")

    monkeypatch.setattr(log_t, "_compute", fail)


@pytest.mark.parametrize("law, n", [("k", 128), ("g0", 24), ("weibull", 64)])
def test_a_cached_factor_is_the_computed_one_bit_for_bit(cache, monkeypatch, law, n):
    want = log_t._compute(law, 1.0, 1e-3, n)
    assert log_t.log_t_exact(law, 1.0, 1e-3, n) == want
    assert len(_files(cache)) == 1
    log_t.log_t_exact.cache_clear()
    _no_compute(monkeypatch)
    got = log_t.log_t_exact(law, 1.0, 1e-3, n)  # read back from disk
    assert got == want and all(a.hex() == b.hex() for a, b in zip(got, want, strict=True))


def test_other_arguments_miss(cache, monkeypatch):
    log_t.log_t_exact("weibull", 1.0, 1e-3, 64)
    calls = []
    real = log_t._compute
    monkeypatch.setattr(log_t, "_compute", lambda *a: calls.append(a) or real(*a))
    for args in [
        ("weibull", 1.0, 1e-4, 64),
        ("weibull", 1.0, 1e-3, 65),
        ("weibull", 2.0, 1e-3, 64),
    ]:
        log_t.log_t_exact(*args)
    assert calls == [
        ("weibull", 1.0, 1e-4, 64),
        ("weibull", 1.0, 1e-3, 65),
        ("weibull", 2.0, 1e-3, 64),
    ]
    assert len(_files(cache)) == 4


@pytest.mark.parametrize(
    "damage",
    ["", "{", "[1, 2]", '{"key": "other", "values": [1.0]}', '{"values": ["x"]}', "\xff"],
)
def test_a_damaged_or_foreign_file_is_recomputed(cache, damage):
    want = log_t._compute("weibull", 1.0, 1e-3, 64)
    log_t.log_t_exact("weibull", 1.0, 1e-3, 64)
    (path,) = _files(cache)
    path.write_text(damage, errors="surrogateescape")
    log_t.log_t_exact.cache_clear()
    assert log_t.log_t_exact("weibull", 1.0, 1e-3, 64) == want


def test_a_stored_key_of_another_version_is_a_miss(cache, monkeypatch):
    log_t.log_t_exact("weibull", 1.0, 1e-3, 64)
    log_t.log_t_exact.cache_clear()
    monkeypatch.setattr(log_t, "_VERSION", "another-version")
    calls = []
    real = log_t._compute
    monkeypatch.setattr(log_t, "_compute", lambda *a: calls.append(a) or real(*a))
    log_t.log_t_exact("weibull", 1.0, 1e-3, 64)
    assert len(calls) == 1


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes anywhere")
def test_an_unwritable_folder_only_costs_time(tmp_path, monkeypatch):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    monkeypatch.setenv(_disk_cache.CACHE_ENV, str(ro / "cache"))
    log_t.log_t_exact.cache_clear()
    assert log_t.log_t_exact("weibull", 1.0, 1e-3, 64) == log_t._compute("weibull", 1.0, 1e-3, 64)
    log_t.log_t_exact.cache_clear()


def test_a_file_in_the_way_only_costs_time(tmp_path, monkeypatch):
    blocker = tmp_path / "cache"
    blocker.write_text("not a folder")
    monkeypatch.setenv(_disk_cache.CACHE_ENV, str(blocker))
    log_t.log_t_exact.cache_clear()
    assert log_t.log_t_exact("weibull", 1.0, 1e-3, 64) == log_t._compute("weibull", 1.0, 1e-3, 64)
    log_t.log_t_exact.cache_clear()


def test_zero_turns_the_cache_off(tmp_path, monkeypatch):
    monkeypatch.setenv(_disk_cache.CACHE_ENV, "0")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("HOME", str(tmp_path))
    log_t.log_t_exact.cache_clear()
    log_t.log_t_exact("weibull", 1.0, 1e-3, 64)
    log_t.log_t_exact.cache_clear()
    assert _disk_cache.cache_dir() is None
    assert not list(tmp_path.rglob("*.json"))


def test_the_default_folder_follows_xdg(tmp_path, monkeypatch):
    monkeypatch.delenv(_disk_cache.CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert _disk_cache.cache_dir() == tmp_path / "xdg" / "torchsar"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert _disk_cache.cache_dir() == tmp_path / "home" / ".cache" / "torchsar"


def test_the_version_tag_changes_with_the_code(tmp_path):
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("x = 1\n")
    b.write_text("x = 2\n")
    assert _disk_cache.version_of(a) != _disk_cache.version_of(b)
    assert _disk_cache.version_of(tmp_path / "missing.py") is None
