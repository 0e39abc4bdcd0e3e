"""Output folders: hilcontact replaces only folders it wrote itself (a marker file says so);
a user's files are never lost, and every refusal or disk error is one line."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import time
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
    assert invoke("run", "paper-table1", *SHORT, "--out", str(out)).exit_code == 0  # its own files: replaced
    (out / "stale.txt").write_text("from an earlier run\n")  # a file it did not write (issue 25): --force
    assert_one_error_line(invoke("run", "paper-table1", *SHORT, "--out", str(out)), "stale.txt", "--force")
    assert invoke("run", "paper-table1", *SHORT, "--out", str(out), "--force").exit_code == 0
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


# ---- paths resolved before any check (issue 25, item 8) -----------------------------------


def _no_temporaries(folder: Path) -> bool:
    return not [p for p in folder.iterdir() if ".tmp-" in p.name or ".old-" in p.name]


@pytest.mark.parametrize("force", [False, True], ids=["plain", "--force"])
def test_out_dotdot_naming_the_current_folder_is_refused_and_kept(tmp_path, force):
    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "notes.txt").write_text("mine\n")
    before = snapshot(proj)
    args = ["run", "paper-table1", "--no-plots", "--out", "../proj", *(["--force"] if force else [])]
    result = invoke(*args, cwd=proj)
    assert_one_error_line(result, "--out ../proj", "current folder")
    assert snapshot(proj) == before and sorted(p.name for p in tmp_path.iterdir()) == ["proj"]


def test_out_dotdot_naming_the_current_run_folder_is_refused(tmp_path):
    d = tmp_path / "d"
    assert invoke("run", "paper-table1", *SHORT, "--out", str(d)).exit_code == 0
    before = snapshot(d)
    for out in ("../d", "../d/", "./../d", "../../" + tmp_path.name + "/d", str(d) + "/sub/.."):
        assert_one_error_line(invoke("run", "paper-table1", *SHORT, "--out", out, cwd=d), "current folder")
    assert snapshot(d) == before and sorted(p.name for p in tmp_path.iterdir()) == ["d"]
    # an ancestor of the current folder, through a symbolic link to it
    (d / "inner").mkdir()
    link = tmp_path / "to-d"
    link.symlink_to(d, target_is_directory=True)
    assert_one_error_line(invoke("run", "paper-table1", *SHORT, "--out", str(link), "--force", cwd=d / "inner"),
                          "current folder or contains it")
    assert (d / MARKER).is_file() and (d / "inner").is_dir()


def test_dotdot_after_a_symbolic_link_is_resolved_as_the_os_does(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b" / "c").mkdir(parents=True)
    (tmp_path / "a" / "link").symlink_to(tmp_path / "b" / "c", target_is_directory=True)
    # a/link/.. is b (the link's target's parent), not a
    assert check_output_folder(tmp_path / "a" / "link" / ".." / "x") == tmp_path / "b" / "x"
    write_atomically(tmp_path / "a" / "link" / ".." / "x", lambda f: (f / "v.txt").write_text("1"), "run")
    assert (tmp_path / "b" / "x" / "v.txt").is_file() and not (tmp_path / "a" / "x").exists()


def test_a_symbolic_link_loop_as_out_is_one_line(tmp_path):
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    result = invoke("run", "paper-table1", *SHORT, "--out", str(tmp_path / "loop"))
    assert_one_error_line(result, "symbolic link loop")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loop"]


# ---- a folder with files hilcontact did not write ------------------------------------------


def test_a_run_folder_with_a_user_s_file_needs_force(tmp_path):
    out = tmp_path / "run"
    assert invoke("run", "paper-table1", *SHORT, "--out", str(out)).exit_code == 0
    (out / "notes.txt").write_text("my notes\n")
    before = snapshot(out)
    result = invoke("run", "paper-table1", *SHORT, "--out", str(out))
    assert_one_error_line(result, "holds files hilcontact did not write", "notes.txt", "--force")
    assert snapshot(out) == before
    # the same from the API
    with pytest.raises(OutputError, match="notes.txt"):
        hc.Run.load(out).save(out, plots=False)
    assert snapshot(out) == before
    assert invoke("run", "paper-table1", *SHORT, "--out", str(out), "--force").exit_code == 0
    assert not (out / "notes.txt").exists() and (out / "metrics.json").is_file()
    assert _no_temporaries(tmp_path)


def test_a_user_s_file_deep_in_a_comparison_folder_needs_force(tmp_path):
    out = tmp_path / "cmp"
    command = ("compare", "paper-table1", "--compensators", "none,pida", *SHORT)
    assert invoke(*command, "--out", str(out)).exit_code == 0
    assert invoke(*command, "--out", str(out)).exit_code == 0  # its own files only: replaced
    (out / "pida" / "mine").mkdir()
    before = snapshot(out)
    assert_one_error_line(invoke(*command, "--out", str(out)), "pida/mine/", "--force")
    assert snapshot(out) == before


def test_a_marker_without_a_list_of_files_needs_force(tmp_path):
    out = tmp_path / "old"
    out.mkdir()
    (out / MARKER).write_text('{"written_by": "hilcontact", "kind": "run"}\n')  # an older hilcontact's
    (out / "metrics.json").write_text("{}")
    result = invoke("run", "paper-table1", *SHORT, "--out", str(out))
    assert_one_error_line(result, "does not list its files", "--force")
    assert (out / "metrics.json").read_text() == "{}"


def test_the_marker_lists_exactly_what_was_written(tmp_path):
    def write(folder: Path) -> None:
        (folder / "a.txt").write_text("a")
        (folder / "sub").mkdir()
        (folder / "sub" / "b.txt").write_text("b")

    write_atomically(tmp_path / "out", write, "run")
    marker = json.loads((tmp_path / "out" / MARKER).read_text())
    assert marker["files"] == ["a.txt", "sub/", "sub/b.txt"] and marker["pid"] == os.getpid()
    write_atomically(tmp_path / "out", lambda f: (f / "c.txt").write_text("c"), "run")  # its own: replaced
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [MARKER, "c.txt"]


# ---- the old folder is renamed aside only once the new one is complete, restored on failure ----


def test_a_failed_swap_puts_the_old_folder_back(tmp_path, monkeypatch):
    out = tmp_path / "out"
    write_atomically(out, lambda f: (f / "old.txt").write_text("old"), "run")
    before = snapshot(out)
    real_rename = os.rename

    def rename(src, dst):
        if ".tmp-" in str(src):  # the new folder into place
            raise OSError(errno.EXDEV, os.strerror(errno.EXDEV), str(src))
        real_rename(src, dst)

    monkeypatch.setattr(os, "rename", rename)
    with pytest.raises(OutputError, match="cannot replace it") as info:
        write_atomically(out, lambda f: (f / "new.txt").write_text("new"), "run")
    assert "\n" not in str(info.value)
    assert snapshot(out) == before and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_swap_whose_old_folder_cannot_be_put_back_says_where_it_is(tmp_path, monkeypatch):
    out = tmp_path / "out"
    write_atomically(out, lambda f: (f / "old.txt").write_text("old"), "run")
    real_rename = os.rename

    def rename(src, dst):
        if ".tmp-" in str(src) or ".old-" in str(src):  # neither the new folder nor the old one back
            raise OSError(errno.EIO, os.strerror(errno.EIO), str(src))
        real_rename(src, dst)

    monkeypatch.setattr(os, "rename", rename)
    with pytest.raises(OutputError, match="kept as") as info:
        write_atomically(out, lambda f: (f / "new.txt").write_text("new"), "run")
    kept = Path(str(info.value).rsplit("kept as ", 1)[1])
    assert (kept / "old.txt").read_text() == "old"  # the user's folder is never deleted


def test_an_error_while_writing_leaves_the_old_folder_untouched(tmp_path):
    out = tmp_path / "out"
    write_atomically(out, lambda f: (f / "old.txt").write_text("old"), "run")
    before = snapshot(out)

    def write(folder: Path) -> None:
        (folder / "part.txt").write_text("partial")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_atomically(out, write, "run")
    assert snapshot(out) == before and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


# ---- concurrent writers: the last one wins and says so --------------------------------------

_WRITER = """
import sys, time, warnings
from pathlib import Path
from hilcontact.output import check_output_folder, write_atomically
out, checked, go, tag = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[4]
check_output_folder(out)
checked.write_text("")
deadline = time.monotonic() + 120
while not go.exists() and time.monotonic() < deadline:
    time.sleep(0.01)
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    write_atomically(out, lambda f: (f / "tag.txt").write_text(tag), "run")
for w in caught:
    print("note:", w.message, file=sys.stderr)
"""


def _python(*args: str) -> subprocess.Popen:
    package_root = str(Path(hc.__file__).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")])))
    return subprocess.Popen([sys.executable, *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(path: Path, proc: subprocess.Popen, seconds: float = 120) -> None:
    deadline = time.monotonic() + seconds
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.01)


def test_a_writer_that_finishes_last_replaces_the_other_s_folder_and_says_so(tmp_path):
    out = tmp_path / "out"
    first = _python("-c", _WRITER, str(out), str(tmp_path / "checked-1"), str(tmp_path / "go-1"), "first")
    _wait_for(tmp_path / "checked-1", first)  # the first has checked the folder (new) ...
    second = _python("-c", _WRITER, str(out), str(tmp_path / "checked-2"), str(tmp_path / "go-2"), "second")
    _wait_for(tmp_path / "checked-2", second)
    (tmp_path / "go-2").write_text("")  # ... the second writes it meanwhile ...
    _, err2 = second.communicate(timeout=120)
    assert second.returncode == 0 and "note:" not in err2, err2
    assert (out / "tag.txt").read_text() == "second"
    (tmp_path / "go-1").write_text("")  # ... then the first finishes: it wins, and says so
    _, err1 = first.communicate(timeout=120)
    assert first.returncode == 0, err1
    notes = [line for line in err1.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and f"process {second.pid}" in notes[0] and "last writer wins" in notes[0], err1
    assert (out / "tag.txt").read_text() == "first"
    assert json.loads((out / MARKER).read_text())["pid"] == first.pid
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(("checked", "go"))) == ["out"]


_HAMMER = """
import sys, time
from pathlib import Path
from hilcontact.output import write_atomically
out, go, tag = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
while not go.exists():
    time.sleep(0.001)
for i in range(8):
    write_atomically(out, lambda f: [(f / f"{tag}-{j}.txt").write_text(tag) for j in range(20)], "run")
"""


def test_concurrent_writers_all_succeed_and_leave_one_complete_folder(tmp_path):
    out, go = tmp_path / "out", tmp_path / "go"
    writers = [_python("-c", _HAMMER, str(out), str(go), f"w{i}") for i in range(3)]
    time.sleep(0.5)
    go.write_text("")
    for proc in writers:
        _, err = proc.communicate(timeout=240)
        assert proc.returncode == 0, err
    marker = json.loads((out / MARKER).read_text())
    assert marker["pid"] in [p.pid for p in writers]
    tag = f"w{[p.pid for p in writers].index(marker['pid'])}"
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, *(f"{tag}-{j}.txt" for j in range(20))])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["go", "out"]


def test_two_cli_runs_into_one_folder_both_succeed_and_the_last_one_wins(core, tmp_path):
    args = ["-m", "hilcontact", "run", "paper-table1", "--set", "simulation.duration=1", "--no-plots", "--out", "out"]
    package_root = str(Path(hc.__file__).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")])))
    procs = [subprocess.Popen([sys.executable, *args], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    errs = [p.communicate(timeout=240)[1] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], errs
    assert all("Traceback" not in e for e in errs)
    winner = json.loads((tmp_path / "out" / MARKER).read_text())["pid"]
    assert winner in [p.pid for p in procs]
    loser = next(i for i, p in enumerate(procs) if p.pid != winner)
    assert "note:" not in errs[loser]  # only the last writer can have replaced the other's folder
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted([MARKER, *hc.run.DATA_FILES])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


# ---- --mcap creates no folders ------------------------------------------------------------


def test_mcap_in_a_missing_folder_is_refused_with_one_line(tmp_path):
    result = invoke("run", "paper-table1", *SHORT, "--out", str(tmp_path / "o"), "--mcap", str(tmp_path / "a" / "b" / "r.mcap"))
    assert_one_error_line(result, "--mcap", "does not exist", "create it first")
    assert list(tmp_path.iterdir()) == []
    for command in (["demo-rt"], ["hil", "paper-table1", "--sensor", "127.0.0.1"]):
        result = invoke(*command, "--out", str(tmp_path / "rt"), "--mcap", str(tmp_path / "a" / "r.mcap"))
        assert_one_error_line(result, "--mcap", "does not exist")
    assert list(tmp_path.iterdir()) == []


# ---- a scenario that is not a file ----------------------------------------------------------


def test_a_scenario_that_is_not_a_regular_file_gets_a_precise_line(tmp_path):
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    (tmp_path / "loop.toml").symlink_to(tmp_path / "loop.toml")
    (tmp_path / "dangling.toml").symlink_to(tmp_path / "missing.toml")
    cases = [
        ("/dev/null", "is a device"),
        (str(fifo), "named pipe"),
        (str(tmp_path / "loop.toml"), "symbolic link loop"),
        (str(tmp_path / "dangling.toml"), "symbolic link to a missing file"),
        (str(tmp_path), "is a directory"),
    ]
    for scenario, fragment in cases:
        result = invoke("run", scenario, "--out", str(tmp_path / "o"))
        line = assert_one_error_line(result, scenario, fragment)
        assert "no such file" not in line
        with pytest.raises(hc.ScenarioError, match=fragment):
            hc.load_scenario(scenario)
    assert not (tmp_path / "o").exists()


def test_only_folders_swapped_into_place_are_reported_written(tmp_path):
    from hilcontact.output import written_folders

    before = written_folders()

    def write(folder: Path) -> None:
        write_atomically(folder / "inner", lambda f: (f / "a.txt").write_text("a"), "run")  # inside staging
        raise KeyboardInterrupt  # the outer one never completes

    with pytest.raises(KeyboardInterrupt):
        write_atomically(tmp_path / "outer", write, "comparison")
    assert written_folders() == before and list(tmp_path.iterdir()) == []
    write_atomically(tmp_path / "outer", lambda f: (f / "b.txt").write_text("b"), "comparison")
    assert written_folders() == [*before, tmp_path / "outer"]
