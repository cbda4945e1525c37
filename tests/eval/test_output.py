"""Run folders: published whole or not at all, never mixed with an older run."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from torchsar_eval.errors import EvalError
from torchsar_eval.names import file_slugs
from torchsar_eval.output import (
    HOST,
    RUN_MARKER,
    StaleRunWarning,
    check_out,
    claim,
    clean,
    hidden_folders,
    recover,
    result_dir,
    write_marker,
)


def _write_run(folder, files):
    for name, text in files.items():
        (folder / name).write_text(text)
    (folder / "config.json").write_text("{}\n")
    write_marker(folder)  # (result_dir writes it again when it publishes)


def _contents(folder):
    return {p.name: p.read_text() for p in folder.iterdir() if p.name != RUN_MARKER}


def _dead_pid():
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_published_whole_with_nothing_left_beside(tmp_path):
    out = tmp_path / "run"
    with result_dir(out) as tmp:
        assert tmp.parent == tmp_path and not out.exists()
        _write_run(tmp, {"a.csv": "1"})
    assert _contents(out) == {"a.csv": "1", "config.json": "{}\n"}
    assert list(tmp_path.iterdir()) == [out]


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_failed_run_leaves_nothing(tmp_path, error):
    out = tmp_path / "run"
    with pytest.raises(error), result_dir(out) as tmp:
        _write_run(tmp, {"a.csv": "1"})
        raise error
    assert list(tmp_path.iterdir()) == []


def test_empty_folder_is_replaced_and_a_full_one_refused(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    with result_dir(out) as tmp:
        _write_run(tmp, {})
    assert _contents(out) == {"config.json": "{}\n"}
    with pytest.raises(EvalError, match="not an empty folder"), result_dir(out):
        pass
    assert _contents(out) == {"config.json": "{}\n"}


@pytest.mark.parametrize(
    ("prepare", "message"),
    [
        (lambda p: p.write_text("x"), "exists and is not a folder"),
        (lambda p: (p.mkdir(), (p / "notes.txt").write_text("x")), "not a run"),
        (lambda p: (p.mkdir(), _write_run(p, {})), "pass overwrite=True"),
    ],
)
def test_claim_refuses_before_any_work(tmp_path, prepare, message):
    out = tmp_path / "out"
    prepare(out)
    before = sorted(os.listdir(tmp_path))
    with pytest.raises(EvalError, match=message), claim(out):
        raise AssertionError("the body must not run")
    assert sorted(os.listdir(tmp_path)) == before


def test_claim_refuses_a_folder_under_a_file(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(EvalError, match="is not a folder"), claim(tmp_path / "f" / "out"):
        pass


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs a read-only /proc")
def test_claim_refuses_an_unwritable_place():
    with pytest.raises(EvalError, match="cannot write in /proc"), claim("/proc/torchsar-out"):
        pass


def test_overwrite_leaves_no_stale_file(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    _write_run(out, {"old.csv": "old", "a.csv": "old"})
    with claim(out, overwrite=True), result_dir(out) as tmp:
        assert not out.exists()  # the old run is aside, not mixed
        _write_run(tmp, {"a.csv": "new"})
    assert _contents(out) == {"a.csv": "new", "config.json": "{}\n"}
    assert list(tmp_path.iterdir()) == [out]


def test_overwrite_keeps_the_old_run_when_the_new_one_fails(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    _write_run(out, {"a.csv": "old"})
    with pytest.raises(RuntimeError), claim(out, overwrite=True), result_dir(out) as tmp:
        _write_run(tmp, {"a.csv": "new"})
        raise RuntimeError
    assert _contents(out) == {"a.csv": "old", "config.json": "{}\n"}
    assert list(tmp_path.iterdir()) == [out]


def _hidden(parent, name, kind, pid, host=None, resumable=False):
    path = parent / f".{name}.torchsar-{kind}-{pid}-0123abcd@{host or HOST}"
    path.mkdir()
    (path / "config.json").write_text(kind)
    if resumable:
        (path / "resume.json").write_text("{}")
        (path / "shard-000000.state").write_text("state")
    return path


@pytest.fixture
def holder():
    """Hold lock files from another, live process (as a running run does)."""
    procs = []

    def hold_in_child(lock):
        code = (
            "import sys; from torchsar_eval.locks import hold\n"
            f"with hold({str(lock)!r}):\n    print('held', flush=True); sys.stdin.read()"
        )
        proc = subprocess.Popen(
            [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        assert proc.stdout.readline().strip() == "held"
        procs.append(proc)
        return proc

    yield hold_in_child
    for proc in procs:
        proc.stdin.close()
        proc.wait(timeout=30)


def test_recover_settles_only_what_ended_runs_left(tmp_path, holder):
    dead = _dead_pid()
    _hidden(tmp_path, "a", "partial", dead)  # staging with nothing to resume: deleted
    _hidden(tmp_path, "b", "replaced", dead)  # old run aside, no new run: put back
    (tmp_path / "c").mkdir()
    _hidden(tmp_path, "c", "replaced", dead)  # old run aside, new one published: deleted
    _hidden(tmp_path, "g", "partial", os.getpid(), host="renamed")  # a reused pid, old name
    running = _hidden(tmp_path, "d", "partial", dead)
    holder(running.with_name(running.name + ".lock"))
    keep = [
        running,  # its lock is held: the run still works, whatever its pid says
        _hidden(tmp_path, "e", "partial", dead, resumable=True),  # saved work: kept, listed
        tmp_path / ".f.partial-123-abc",  # not named by us
    ]
    keep[-1].mkdir()
    stale_lock = tmp_path / f".h.torchsar-partial-{dead}-0123abcd@{HOST}.lock"
    stale_lock.write_text("")  # killed between creating its lock and its folder
    with pytest.warns(StaleRunWarning, match=r"\.e\.torchsar.*1 saved shard.*--resume --out"):
        settled = recover(tmp_path)
    assert sorted(h.name for h in settled) == ["a", "b", "c", "g"]
    assert (tmp_path / "b" / "config.json").read_text() == "replaced"
    names = sorted(os.listdir(tmp_path))
    assert names == sorted(["b", "c", running.name + ".lock", *(p.name for p in keep)])


def test_resume_adopts_the_staging_folder_of_an_ended_run(tmp_path):
    out = tmp_path / "out"
    left = _hidden(tmp_path, "out", "partial", _dead_pid(), host="old-name", resumable=True)
    with claim(out, resume=True), result_dir(out, resume=True) as tmp:
        assert (tmp / "shard-000000.state").read_text() == "state"
        (tmp / "summary.csv").write_text("x")
    assert not left.exists()
    assert sorted(os.listdir(out)) == [
        RUN_MARKER,
        "config.json",
        "resume.json",
        "shard-000000.state",
        "summary.csv",
    ]
    assert list(tmp_path.iterdir()) == [out]


FAILURES = [
    EvalError("shard 3 failed"),
    OSError(28, "No space left on device"),
    KeyboardInterrupt(),
    RuntimeError("a bug"),
]


@pytest.mark.parametrize("error", FAILURES)
def test_a_failed_run_keeps_its_saved_work_for_resume(tmp_path, error):
    out = tmp_path / "out"
    with (
        pytest.raises((EvalError, type(error))) as caught,
        claim(out),
        result_dir(out, keep=True) as tmp,
    ):
        (tmp / "resume.json").write_text("{}")
        (tmp / "shard-000000.state").write_text("state")
        raise error
    (kept,) = [h for h in hidden_folders(tmp_path)]
    assert (kept.path / "shard-000000.state").read_text() == "state" and not kept.alive
    if isinstance(error, EvalError | OSError):
        message = str(caught.value)
        assert f"kept in {kept.path}" in message and "resume=True" in message
        assert "No space left" in message or "shard 3 failed" in message
    # a new run of the same folder is refused; resume continues the saved work
    with pytest.raises(EvalError, match="saved work .*resume=True.*discard=True"):
        check_out(out)
    with claim(out, resume=True), result_dir(out, resume=True, keep=True) as tmp:
        assert (tmp / "shard-000000.state").read_text() == "state"
        (tmp / "config.json").write_text("{}")
    assert list(tmp_path.iterdir()) == [out]


def test_without_keep_or_saved_work_a_failed_run_leaves_nothing(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(EvalError), claim(out), result_dir(out, keep=True) as tmp:
        (tmp / "summary.csv").write_text("x")  # no resume.json: nothing to resume
        raise EvalError("bad dataset")
    assert list(tmp_path.iterdir()) == []


def test_discard_deletes_the_saved_work(tmp_path):
    out = tmp_path / "out"
    left = _hidden(tmp_path, "out", "partial", _dead_pid(), resumable=True)
    with claim(out, discard=True), result_dir(out) as tmp:
        assert not left.exists() and list(tmp.iterdir()) == []
        (tmp / "config.json").write_text("{}")
    assert list(tmp_path.iterdir()) == [out]
    with pytest.raises(EvalError, match="exclude each other"):
        check_out(tmp_path / "x", resume=True, discard=True)


def test_a_folder_another_run_writes_is_refused(tmp_path, holder):
    out = tmp_path / "out"
    running = _hidden(tmp_path, "out", "partial", 1, resumable=True)
    holder(running.with_name(running.name + ".lock"))
    for kwargs in ({}, {"resume": True}, {"discard": True}):
        with pytest.raises(EvalError, match="being written by another run"):
            check_out(out, **kwargs)
    assert running.exists()


def test_clean_deletes_ended_runs_only(tmp_path, holder):
    runs = tmp_path / "results"
    runs.mkdir()
    ended = _hidden(runs, "a", "partial", _dead_pid(), resumable=True)
    other = _hidden(runs, "b", "partial", _dead_pid(), resumable=True)
    running = _hidden(runs, "c", "partial", 1, resumable=True)
    holder(running.with_name(running.name + ".lock"))
    assert [h.path for h in clean(runs / "a", dry_run=True)] == [ended]
    assert ended.exists()
    assert [h.path for h in clean(runs / "a")] == [ended]
    assert not ended.exists() and other.exists()
    assert [h.path for h in clean(runs)] == [other]
    assert sorted(os.listdir(runs)) == sorted([running.name, running.name + ".lock"])


# --- crash consistency: a process killed before any single file-system step -------------


def _overwrite_run(out):
    with claim(out, overwrite=True), result_dir(out) as tmp:
        for name in ("a.csv", "b.csv", "config.json"):
            _step("write")
            (tmp / name).write_text("new")


def _step(kind):
    """Count one file-system step; die like SIGKILL (no clean-up) at the chosen one."""
    _step.count += 1
    if _step.count == _step.kill_at:
        os._exit(9)


def _counted(name, real):
    def call(*args, **kwargs):
        _step(name)
        return real(*args, **kwargs)

    return call


def _killed_at(out, k):
    """Run ``_overwrite_run`` in a child killed at step ``k``; True if it finished first."""
    pid = os.fork()
    if pid == 0:  # child: patches its own copy of os and shutil, never returns into pytest
        try:
            _step.count, _step.kill_at = 0, k
            for mod, name in ((os, "rename"), (os, "mkdir"), (shutil, "rmtree")):
                setattr(mod, name, _counted(name, getattr(mod, name)))
            _overwrite_run(out)
        finally:
            os._exit(0)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status) == 0


def test_a_kill_at_any_step_leaves_the_old_or_the_new_run(tmp_path):
    out = tmp_path / "out"
    outcomes = set()
    for k in range(1, 40):
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir()
        for name in ("a.csv", "stale.csv", "config.json"):
            (out / name).write_text("old")
        write_marker(out)
        finished = _killed_at(out, k)
        recover(tmp_path)
        contents = _contents(out)
        assert contents in (
            {"a.csv": "old", "stale.csv": "old", "config.json": "old"},
            {"a.csv": "new", "b.csv": "new", "config.json": "new"},
        ), k
        assert list(tmp_path.iterdir()) == [out], k
        outcomes.add(contents["a.csv"])
        if finished:
            break
    assert finished and outcomes == {"old", "new"}


def test_file_slugs_are_unique_per_run():
    names = ["sim", "folder:a/x", "folder:b/x", "folder:b/x", "folder_a_x"]
    slugs = file_slugs(names, lambda n: n.rsplit("/", 1)[-1])
    assert slugs == {
        "sim": "sim",  # unique: unchanged
        "folder:a/x": "folder_a_x",
        "folder:b/x": "folder_b_x",
        "folder_a_x": "folder_a_x-2",
    }


def _tree(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.parametrize(
    "prepare",
    [
        # a model or project folder that happens to hold a config.json
        lambda p: (
            (p / "config.json").write_text("{}"),
            (p / "weights").mkdir(),
            (p / "weights" / "model.pt").write_text("w"),
        ),
        # a run of ours to which the user added a file
        lambda p: (_write_run(p, {"a.csv": "1"}), (p / "notes.txt").write_text("mine")),
        # a run of ours with a link added (never followed, never deleted)
        lambda p: (_write_run(p, {"a.csv": "1"}), (p / "data").symlink_to(p.parent)),
        # a marker that is not ours
        lambda p: ((p / RUN_MARKER).write_text('{"tool": "other", "files": []}'),),
    ],
)
def test_overwrite_touches_only_what_a_run_wrote(tmp_path, prepare):
    out = tmp_path / "out"
    out.mkdir()
    prepare(out)
    before = _tree(out)
    with pytest.raises(EvalError, match="not a run of torchsar-eval"), claim(out, overwrite=True):
        raise AssertionError("the body must not run")
    assert _tree(out) == before


def test_a_published_run_lists_every_file_and_is_replaced(tmp_path):
    out = tmp_path / "out"
    with result_dir(out) as tmp:
        (tmp / "sub").mkdir()
        _write_run(tmp, {"a.csv": "1", "sub/b.csv": "2"})
    record = json.loads((out / RUN_MARKER).read_text())
    assert record["files"] == ["a.csv", "config.json", "sub/b.csv"]
    with claim(out, overwrite=True), result_dir(out) as tmp:
        _write_run(tmp, {"c.csv": "3"})
    assert _contents(out) == {"c.csv": "3", "config.json": "{}\n"}
