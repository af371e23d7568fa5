"""The fault suite, part 3 (issue: hardening 3): a job folder, a spec or a dataset made by someone
else cannot be turned against the user who runs the toolkit on it, and no input ends in a
traceback. Each case asserts the exit status (or the error type a command maps to exit 2), the
one-line message, and what is left behind; docs/testing.md#security says what is promised.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml

from formats.atomic import replacing, temp_name, write_json_atomic, write_nofollow
from formats.errors import UserError
from formats.lifetime import FolderLock


# ---------------------------------------------------------------------------------------------
# links: nothing the toolkit writes goes through a link it did not make


def _victim(tmp_path) -> Path:
    v = tmp_path / "victim.txt"
    v.write_text("precious\n")
    return v


@pytest.mark.parametrize("what", ["link", "folder"])
def test_a_lock_that_is_a_link_or_a_folder_is_refused(tmp_path, what):
    victim = _victim(tmp_path)
    job = tmp_path / "job"
    job.mkdir()
    if what == "link":
        (job / ".lock").symlink_to(victim)
    else:
        (job / ".lock").mkdir()
    with pytest.raises(UserError) as e:
        FolderLock(job, "synth render").acquire()
    msg = str(e.value)
    assert "\n" not in msg and str(job / ".lock") in msg
    assert ("symbolic link" in msg) if what == "link" else ("is a folder" in msg)
    assert victim.read_text() == "precious\n"  # not truncated, no pid written into it
    assert (job / ".lock").is_symlink() if what == "link" else (job / ".lock").is_dir()


def test_a_render_into_a_job_folder_with_a_planted_lock_link_exits_2(tmp_path, capsys):
    from synth.cli import main as synth_main

    victim = _victim(tmp_path)
    spec = {"name": "lk", "out": str(tmp_path / "job"), "renderer": "fast", "size": [32, 24],
            "designs": [{"layouts": ["apt_0"], "path": {"name": "query", "frames": 3}}]}
    (tmp_path / "job.yaml").write_text(yaml.safe_dump(spec))
    (tmp_path / "job").mkdir()
    (tmp_path / "job" / ".lock").symlink_to(victim)
    for extra in ([], ["--resume"]):
        assert synth_main(["render", str(tmp_path / "job.yaml"), "--quiet", *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "symbolic link" in err, err
    assert victim.read_text() == "precious\n"
    assert sorted(p.name for p in (tmp_path / "job").iterdir()) == [".lock"]  # nothing rendered


def test_an_atomic_write_replaces_a_planted_link_and_ignores_a_planted_temporary_link(tmp_path):
    victim = _victim(tmp_path)
    target = tmp_path / "out" / "results.json"
    target.parent.mkdir()
    target.symlink_to(victim)  # a link where the file goes: replaced, not followed
    temp_name(target).symlink_to(tmp_path / "victim.txt")  # a link where the temporary file goes
    write_json_atomic(target, {"a": 1})
    assert victim.read_text() == "precious\n"
    assert not target.is_symlink() and target.read_text().startswith("{")
    assert not os.path.lexists(temp_name(target))
    folder = tmp_path / "out" / "dir.json"
    folder.mkdir()
    with pytest.raises(UserError, match="is a folder"):
        with replacing(folder) as tmp:
            tmp.write_text("x")


def test_job_files_and_logs_refuse_a_link(tmp_path):
    victim = _victim(tmp_path)
    log = tmp_path / "chunk.log"
    log.symlink_to(victim)
    with pytest.raises(UserError, match="symbolic link"):
        write_nofollow(log, "job\n")
    assert victim.read_text() == "precious\n"
    write_nofollow(tmp_path / "fresh.log", "ok\n")
    assert (tmp_path / "fresh.log").read_text() == "ok\n"
