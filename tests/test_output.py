"""Output folders: hilcontact replaces only folders it wrote itself (a marker file says so);
a user's files are never lost, and every refusal or disk error is one line."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

import hilcontact as hc
from hilcontact.output import MARKER, OutputError, check_output_folder, write_atomically
from test_cli import assert_one_error_line, invoke

SHORT = ("--set", "simulation.duration=0.3", "--no-plots")


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else b"/" for p in sorted(folder.rglob("*"))}


def test_out_dot_in_a_folder_of_user_files_refuses_and_keeps_them(tmp_path):
    (tmp_path / "my.toml").write_text(hc.load_scenario("paper-table1").to_toml())
    (tmp_path / "keep.txt").write_text("keep me\n")
    before = snapshot(tmp_path)
    result = invoke("run", "paper-table1", *SHORT, "--out", ".", cwd=tmp_path)
    assert_one_error_line(result, "--out .", "current folder")
    assert snapshot(tmp_path) == before
    # --force does not make the current folder replaceable
    result = invoke("run", "paper-table1", *SHORT, "--out", ".", "--force", cwd=tmp_path)
    assert_one_error_line(result, "current folder")
    assert snapshot(tmp_path) == before


def test_a_folder_of_user_files_is_refused_before_running_and_force_replaces_it(tmp_path):
    out = tmp_path / "results"
    (out / "mydata").mkdir(parents=True)
    (out / "notes.txt").write_text("notes\n")
    (out / "mydata" / "a.csv").write_text("1,2\n")
    before = snapshot(out)
    for command in (["run", "paper-table1"], ["compare", "paper-table1", "--compensators", "none,pida"]):
        result = invoke(*command, *SHORT, "--out", str(out))
        assert_one_error_line(result, "holds files hilcontact did not write", "mydata/", "notes.txt", "--force")
        assert snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results"]  # no temporary folder
    result = invoke("run", "paper-table1", *SHORT, "--out", str(out), "--force")
    assert result.exit_code == 0, result.output
    assert (out / "metrics.json").is_file() and (out / MARKER).is_file()
    assert not (out / "notes.txt").exists()


def test_a_folder_hilcontact_wrote_is_replaced_and_an_empty_one_is_used(tmp_path):
    out = tmp_path / "run"
    out.mkdir()  # empty: fine
    assert invoke("run", "paper-table1", *SHORT, "--out", str(out)).exit_code == 0
    (out / "stale.txt").write_text("from an earlier run\n")  # inside a hilcontact folder
    assert invoke("run", "paper-table1", *SHORT, "--out", str(out)).exit_code == 0
    assert not (out / "stale.txt").exists() and (out / "metrics.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_sweep_into_a_run_folder_or_user_files_is_refused(tmp_path):
    run_folder = tmp_path / "run"
    assert invoke("run", "paper-table1", *SHORT, "--out", str(run_folder)).exit_code == 0
    before = snapshot(run_folder)
    sweep = ("sweep", "paper-table1", "--grid", "servicer.mass=300", "--compensators", "none",
             "--set", "simulation.duration=0.3")
    result = invoke(*sweep, "--out", str(run_folder))
    assert_one_error_line(result, "a hilcontact run folder", "a sweep needs a new or empty folder")
    assert snapshot(run_folder) == before
    user = tmp_path / "user"
    user.mkdir()
    (user / "notes.txt").write_text("x\n")
    assert_one_error_line(invoke(*sweep, "--out", str(user)), "files hilcontact did not write")
    assert snapshot(user) == {"notes.txt": b"x\n"}
    fresh = tmp_path / "sweep"
    assert invoke(*sweep, "--out", str(fresh)).exit_code == 0
    assert (fresh / MARKER).is_file()


def test_a_symlinked_out_writes_into_the_linked_folder_and_keeps_the_link(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    assert invoke("run", "paper-table1", *SHORT, "--out", str(link)).exit_code == 0
    assert link.is_symlink() and (real / "metrics.json").is_file()
    assert invoke("run", "paper-table1", *SHORT, "--out", str(link)).exit_code == 0  # again
    assert link.is_symlink() and (real / "metrics.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real"]  # no .old-* left behind


def test_out_under_a_file_is_one_line(tmp_path):
    (tmp_path / "afile").write_text("x")
    result = invoke("run", "paper-table1", *SHORT, "--out", str(tmp_path / "afile" / "sub"))
    assert_one_error_line(result, "afile", "is a file")
    assert (tmp_path / "afile").read_text() == "x"


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EACCES, errno.EROFS])
def test_disk_and_permission_errors_are_one_line_and_leave_nothing(tmp_path, monkeypatch, code):
    out = tmp_path / "out"

    def write(folder: Path) -> None:
        (folder / "a.txt").write_text("partial")
        raise OSError(code, os.strerror(code), str(folder / "b.parquet"))

    with pytest.raises(OutputError) as info:
        write_atomically(out, write, "run")
    message = str(info.value)
    assert "\n" not in message and os.strerror(code) in message and "b.parquet" in message
    assert list(tmp_path.iterdir()) == []  # no temporary folder, no output
    # while creating the staging folder
    monkeypatch.setattr(os, "mkdir", lambda *a, **k: (_ for _ in ()).throw(OSError(code, os.strerror(code))))
    with pytest.raises(OutputError, match="cannot create it"):
        write_atomically(out, lambda folder: None, "run")


def test_check_output_folder_returns_the_folder_to_write(tmp_path):
    assert check_output_folder(tmp_path / "new") == (tmp_path / "new").absolute()
    with pytest.raises(OutputError, match="current folder"):
        check_output_folder(Path.cwd().parent)
