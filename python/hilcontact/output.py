"""Output folders: hilcontact replaces only folders it wrote itself, never a user's files.

Every folder hilcontact writes (a run, a comparison, a sweep, a stability map) holds a marker
file, :data:`MARKER`, saying so. An output folder (``--out``) may be:

- new, or an existing empty folder: written;
- a folder with the marker: replaced as a whole, atomically (a temporary sibling folder is
  written, then swapped in by renames: an existing folder is never half-overwritten, and
  nothing is left behind when writing fails);
- anything else (a folder with the user's own files, the current folder or one that contains
  it, a file): refused with one line naming the folder and what it holds, before anything is
  computed (:func:`check_output_folder`); ``overwrite=True`` (CLI ``--force``) replaces a
  folder with foreign files, never the current folder.

A symbolic link to a folder is followed: the folder it points to is checked and replaced, the
link stays. Disk and permission errors become a :class:`OutputError` naming the path.

Temporary names carry the writing process's id (``.NAME.tmp-<pid>-<hex>``,
``.NAME.old-<pid>-<hex>``). A process stopped by SIGTERM or Ctrl-C removes its own; one that
was killed outright (SIGKILL, a power cut) cannot, so the next write next to them removes the
temporary folders and files of processes that no longer run (:func:`remove_stale`), and
puts back an ``.old-`` folder whose swap was cut short.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import uuid
from collections.abc import Callable
from pathlib import Path

from .errors import HilContactError

__all__ = ["MARKER", "OutputError", "check_output_folder", "remove_stale", "staging_name", "write_atomically"]

#: Name of the marker file in every folder hilcontact writes.
MARKER = ".hilcontact.json"


class OutputError(HilContactError, ValueError):
    """An output folder that hilcontact will not write (it holds a user's files, it is the
    current folder, it is a file), or a disk or permission error while writing; the message is
    one line naming the path."""


def staging_name(name: str, kind: str = "tmp") -> str:
    """A hidden temporary name next to ``name``, with this process's id: ``.NAME.tmp-<pid>-<hex>``."""
    return f".{name}.{kind}-{os.getpid()}-{uuid.uuid4().hex[:12]}"


_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.(?P<kind>tmp|old)-(?P<pid>\d+)-[0-9a-f]+$")


def _running(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # e.g. another user's process
        return True
    return True


def remove_stale(folder: Path, name: str | None = None) -> None:
    """Remove the temporary folders and files in ``folder`` (of ``name`` only, if given) that
    processes no longer running left behind; an ``.old-`` folder whose target is missing (its
    swap was cut short) is put back instead. Errors are ignored: this only tidies."""
    try:
        entries = list(folder.iterdir())
    except OSError:
        return
    for entry in entries:
        match = _TEMPORARY.match(entry.name)
        if match is None or (name is not None and match["name"] != name) or _running(int(match["pid"])):
            continue
        target = folder / match["name"]
        try:
            if match["kind"] == "old" and not target.exists():
                os.rename(entry, target)
            elif entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry, ignore_errors=True)
            else:
                entry.unlink()
        except OSError:
            pass


def _describe(folder: Path, limit: int = 3) -> str:
    names = sorted(p.name + ("/" if p.is_dir() else "") for p in folder.iterdir())
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def _resolved(directory: str | os.PathLike[str]) -> Path:
    """The folder to write: ``directory`` made absolute, a symbolic link followed."""
    target = Path(directory)
    if target.is_symlink():
        target = target.resolve()
    return target.absolute()


def check_output_folder(directory: str | os.PathLike[str], overwrite: bool = False) -> Path:
    """Check that ``directory`` may be written (see the module doc) before anything is computed;
    returns the folder that will be written (absolute, links followed). Raises
    :class:`OutputError`."""
    target = _resolved(directory)
    if target.exists() and not target.is_dir():
        raise OutputError(f"--out {directory}: exists and is not a directory")
    cwd = Path.cwd().absolute()
    if target == cwd or target in cwd.parents:
        raise OutputError(
            f"--out {directory}: is the current folder or contains it; choose a new folder, e.g. --out runs/NAME"
        )
    for parent in target.parents:
        if parent.exists() and not parent.is_dir():
            raise OutputError(f"--out {directory}: {parent} is a file, not a folder")
    if target.is_dir() and not overwrite and not (target / MARKER).is_file():
        try:
            empty = not any(target.iterdir())
        except OSError as exc:
            raise OutputError(f"--out {directory}: cannot read it: {exc.strerror or exc}") from None
        if not empty:
            raise OutputError(
                f"--out {directory}: holds files hilcontact did not write ({_describe(target)}); "
                "choose another folder, or add --force to replace it"
            )
    return target


def write_atomically(
    directory: str | os.PathLike[str],
    write: Callable[[Path], None],
    kind: str,
    overwrite: bool = False,
) -> Path:
    """Call ``write(folder)`` on a temporary sibling folder of ``directory``, add the marker
    (``kind``: ``run``, ``comparison``, ...), then swap it into place. Checks ``directory``
    first (:func:`check_output_folder`). Returns ``directory`` as a Path."""
    target = check_output_folder(directory, overwrite)
    # os.mkdir (not tempfile.mkdtemp) so that the folder gets the usual permissions
    staging = target.parent / staging_name(target.name)
    try:  # one try from mkdir to swap: whatever stops it (an error, Ctrl-C, SIGTERM) removes staging
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            remove_stale(target.parent, target.name)
            os.mkdir(staging)
        except OSError as exc:
            raise OutputError(f"--out {directory}: cannot create it: {exc.strerror or exc}") from None
        try:
            write(staging)
            (staging / MARKER).write_text(json.dumps({"written_by": "hilcontact", "kind": kind}) + "\n", encoding="utf-8")
        except OSError as exc:
            where = exc.filename if exc.filename else directory
            raise OutputError(f"--out {directory}: cannot write {where}: {exc.strerror or exc}") from None
        try:
            _swap_into_place(staging, target)
        except OSError as exc:
            raise OutputError(f"--out {directory}: cannot replace it: {exc.strerror or exc}") from None
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return Path(directory)


def _swap_into_place(staging: Path, target: Path) -> None:
    """Replace ``target`` by ``staging`` (same parent folder) with renames only."""
    old: Path | None = None
    if target.exists():
        old = target.parent / staging_name(target.name, "old")
        os.rename(target, old)
    try:
        os.rename(staging, target)
    except BaseException:
        if old is not None:
            os.rename(old, target)
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def marker_kind(folder: Path) -> str | None:
    """The kind a folder's marker names (``run``, ``comparison``, ``sweep``), ``"unknown"`` for
    an unreadable marker, None without one."""
    try:
        text = (folder / MARKER).read_text(encoding="utf-8")
    except OSError:
        return None
    try:
        kind = json.loads(text).get("kind")
    except (ValueError, AttributeError):
        return "unknown"
    return str(kind) if kind else "unknown"


def mark_folder(folder: Path, kind: str) -> None:
    """Write the marker into a folder hilcontact fills in place (a sweep, a stability map)."""
    (folder / MARKER).write_text(json.dumps({"written_by": "hilcontact", "kind": kind}) + "\n", encoding="utf-8")
