"""Output folders: hilcontact replaces only folders it wrote itself, never a user's files.

Every folder hilcontact writes (a run, a comparison, a replay) holds a marker file,
:data:`MARKER`, saying so and listing every file and folder it wrote (``files``; a sweep,
written in place, lists none). An output folder (``--out``) may be:

- new, or an existing empty folder: written;
- a folder with the marker and nothing but the files it lists: replaced as a whole,
  atomically (a temporary sibling folder is written, then swapped in by renames once it is
  complete: an existing folder is never half-overwritten, and nothing is left behind when
  writing fails);
- anything else (a folder with the user's own files, even inside a folder hilcontact wrote;
  a marker that lists no files; the current folder or one that contains it; a file): refused
  with one line naming the folder and what it holds, before anything is computed
  (:func:`check_output_folder`); ``overwrite=True`` (CLI ``--force``) replaces a folder with
  foreign files, never the current folder or one that contains it.

The path is resolved before any check: ``..`` collapsed and symbolic links followed (a link to
a folder: the folder it points to is checked and replaced, the link stays; a link loop is
refused). Disk and permission errors become an :class:`OutputError` naming the path.

Two processes writing the same folder: the swaps are serialised (a lock on the parent folder,
held only while renaming) and the folder is checked again under the lock; the last one wins,
and when the folder it replaces was written by another process after this one checked it, it
says so (a :class:`ReplacedWhileRunning` warning; the CLI prints it as a ``note:`` line).

Temporary names carry the writing process's id (``.NAME.tmp-<pid>-<hex>``,
``.NAME.old-<pid>-<hex>``). The swap's two renames run with Ctrl-C and SIGTERM held back (they
take effect right after it), and a failed second rename puts the old folder back. A process
stopped by SIGTERM or Ctrl-C removes its own temporary folders; one that was killed outright
(SIGKILL, a power cut) cannot, so the next write next to them removes the temporary folders
and files of processes that no longer run (:func:`remove_stale`), and puts back an ``.old-``
folder whose swap was cut short.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import threading
import time
import uuid
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .errors import HilContactError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: swaps are not serialised across processes
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "MARKER",
    "OutputError",
    "ReplacedWhileRunning",
    "check_output_folder",
    "remove_stale",
    "resolve_path",
    "signals_held",
    "staging_name",
    "write_atomically",
    "note_written",
    "written_folders",
]

#: Name of the marker file in every folder hilcontact writes.
MARKER = ".hilcontact.json"


class OutputError(HilContactError, ValueError):
    """An output folder that hilcontact will not write (it holds a user's files, it is the
    current folder, it is a file), or a disk or permission error while writing; the message is
    one line naming the path."""


class ReplacedWhileRunning(UserWarning):
    """An output folder was written by another process after this one checked it, and this
    one replaced it (the last writer wins); the message names the folder and the process."""


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
            if match["kind"] == "old" and not os.path.lexists(target):
                os.rename(entry, target)
            elif entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry, ignore_errors=True)
            else:
                entry.unlink()
        except OSError:
            pass


def _describe(names: list[str], limit: int = 3) -> str:
    shown = ", ".join(sorted(names)[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def resolve_path(path: str | os.PathLike[str], what: str) -> Path:
    """``path`` made absolute with ``..`` collapsed and every symbolic link followed (as the
    OS will follow them), whether or not it exists; ``what`` (``--out DIR``) names it in the
    :class:`OutputError` raised for a link loop or a path that cannot be read."""
    if "\x00" in os.fspath(path):
        raise OutputError(f"{what}: a path cannot hold a NUL character")
    try:
        return Path(path).resolve()
    except RuntimeError:  # Python < 3.13: "Symlink loop from ..."
        raise OutputError(f"{what}: a symbolic link loop; give a real folder") from None
    except OSError as exc:
        if exc.errno == getattr(os, "ELOOP", 40):
            raise OutputError(f"{what}: a symbolic link loop; give a real folder") from None
        raise OutputError(f"{what}: cannot resolve it: {exc.strerror or exc}") from None


def _listing(folder: Path) -> list[str]:
    """Every file and folder under ``folder`` (links not followed), as POSIX paths relative to
    it (folders with a trailing ``/``), the marker excluded; sorted."""
    names: list[str] = []
    for root, dirs, files in os.walk(folder):
        here = Path(root).relative_to(folder)
        names += [(here / d).as_posix() + "/" for d in dirs]
        names += [(here / f).as_posix() for f in files]
    return sorted(n for n in names if n != MARKER)


def _read_marker(folder: Path) -> dict[str, Any] | None:
    """The marker's content (``{}`` when unreadable), None without one."""
    try:
        text = (folder / MARKER).read_text(encoding="utf-8")
    except OSError:
        return None
    try:
        data = json.loads(text)
    except ValueError:
        return {}
    return data if isinstance(data, dict) else {}


def _foreign(folder: Path, marker: dict[str, Any] | None) -> list[str] | None:
    """What in ``folder`` hilcontact did not write: the entries its marker does not list (every
    entry without a marker), None when the marker lists no files (a folder written in place,
    or by an older hilcontact)."""
    listed = marker.get("files") if marker is not None else []
    if not isinstance(listed, list):
        return None
    listed_set = set(map(str, listed))
    return [name for name in _listing(folder) if name not in listed_set]


def _checked_at(target: Path) -> float:
    """When this process first checked ``target`` (now if never): a folder that another
    process writes after this moment was written while this one ran."""
    return _CHECKED.setdefault(target, time.time())


_CHECKED: dict[Path, float] = {}


def check_output_folder(directory: str | os.PathLike[str], overwrite: bool = False) -> Path:
    """Check that ``directory`` may be written (see the module doc) before anything is computed;
    returns the folder that will be written (absolute, ``..`` collapsed, links followed).
    Raises :class:`OutputError`."""
    target = resolve_path(directory, f"--out {directory}")
    _checked_at(target)
    if target.parent.is_dir():
        # under the swap's lock: another process's swap, between its two renames, would show
        # one folder's marker and the other's files
        with _swap_lock(target.parent):
            _check_target(directory, target, overwrite)
    else:
        _check_target(directory, target, overwrite)
    return target


def _check_target(directory: str | os.PathLike[str], target: Path, overwrite: bool) -> None:
    try:
        cwd = Path.cwd().resolve()
    except OSError:  # the current folder was removed: it cannot be the one written
        cwd = None
    if cwd is not None and (target == cwd or target in cwd.parents):
        raise OutputError(
            f"--out {directory}: is the current folder or contains it; choose a new folder, e.g. --out runs/NAME"
        )
    for parent in target.parents:
        if parent.exists() and not parent.is_dir():
            raise OutputError(f"--out {directory}: {parent} is a file, not a folder")
    if os.path.lexists(target) and not target.is_dir():
        raise OutputError(f"--out {directory}: exists and is not a directory")
    if not target.is_dir() or overwrite:
        return
    marker = _read_marker(target)
    try:
        foreign = _foreign(target, marker)
    except OSError as exc:
        raise OutputError(f"--out {directory}: cannot read it: {exc.strerror or exc}") from None
    if foreign is None:
        kind = marker.get("kind", "unknown") if marker else "unknown"
        raise OutputError(
            f"--out {directory}: a hilcontact {kind} folder that does not list its files (written in place, "
            "or by an older hilcontact); choose another folder, or add --force to replace it"
        )
    if foreign:
        raise OutputError(
            f"--out {directory}: holds files hilcontact did not write ({_describe(foreign)}); "
            "choose another folder, or add --force to replace it"
        )


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) and SIGTERM back for the duration of the block (a few renames):
    a signal that comes meanwhile takes effect, with its usual handler, right after it. Only in
    the main thread (the only one whose handlers Python lets change); elsewhere a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []
    held = (signal.SIGINT, signal.SIGTERM)
    previous = {sig: signal.getsignal(sig) for sig in held}
    for sig in held:
        signal.signal(sig, lambda signum, _frame: came.append(signum))
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        for sig in dict.fromkeys(came):
            signal.raise_signal(sig)


@contextmanager
def _swap_lock(parent: Path) -> Iterator[None]:
    """An exclusive lock on the folder ``parent`` (flock): one swap at a time next to it,
    across processes; released when the block ends or the process dies (a no-op without
    ``fcntl``)."""
    if fcntl is None:  # pragma: no cover
        yield
        return
    fd = os.open(parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def write_atomically(
    directory: str | os.PathLike[str],
    write: Callable[[Path], None],
    kind: str,
    overwrite: bool = False,
) -> Path:
    """Call ``write(folder)`` on a temporary sibling folder of ``directory``, add the marker
    (``kind``: ``run``, ``comparison``, ...; with the list of what ``write`` wrote), then swap
    it into place. Checks ``directory`` first (:func:`check_output_folder`) and again under the
    swap's lock. Returns ``directory`` as a Path."""
    target = check_output_folder(directory, overwrite)
    # os.mkdir (not tempfile.mkdtemp) so that the folder gets the usual permissions
    staging = target.parent / staging_name(target.name)
    old: Path | None = None
    swapped = False
    try:  # one try from mkdir to swap: whatever stops it (an error, Ctrl-C, SIGTERM) removes staging
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            remove_stale(target.parent, target.name)
            os.mkdir(staging)
        except OSError as exc:
            raise OutputError(f"--out {directory}: cannot create it: {exc.strerror or exc}") from None
        try:
            _NESTING.depth += 1  # what `write` saves inside staging is not saved yet
            try:
                write(staging)
            finally:
                _NESTING.depth -= 1
            marker = {"written_by": "hilcontact", "kind": kind, "pid": os.getpid(), "time": time.time(),
                      "files": _listing(staging)}
            (staging / MARKER).write_text(json.dumps(marker) + "\n", encoding="utf-8")
        except OSError as exc:
            where = exc.filename if exc.filename else directory
            raise OutputError(f"--out {directory}: cannot write {where}: {exc.strerror or exc}") from None
        try:
            with signals_held(), _swap_lock(target.parent):
                _check_target(directory, target, overwrite)  # it may have changed while this one ran
                _note_replaced(directory, target)
                old = _swap_into_place(staging, target, directory)
                swapped = True
        except OSError as exc:
            raise OutputError(f"--out {directory}: cannot replace it: {exc.strerror or exc}") from None
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    finally:  # the swap done (a held-back Ctrl-C may be on its way): the old folder goes
        if swapped and _NESTING.depth == 0:
            _WRITTEN.append(Path(directory))
            _CHECKED.pop(target, None)  # a later write checks afresh
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    return Path(directory)


_WRITTEN: list[Path] = []


class _Nesting(threading.local):
    """How many :func:`write_atomically` calls of this thread are writing their staging
    folder (a comparison's runs are written inside the comparison's)."""

    depth = 0


_NESTING = _Nesting()


def written_folders() -> list[Path]:
    """The folders (and files, :func:`note_written`) this process has written completely so
    far, as given; what a command stopped by Ctrl-C reports having saved."""
    return list(_WRITTEN)


def note_written(path: str | os.PathLike[str]) -> None:
    """Record a file written completely outside :func:`write_atomically` (a run's MCAP
    recording), for :func:`written_folders`."""
    _WRITTEN.append(Path(path))


def _note_replaced(directory: str | os.PathLike[str], target: Path) -> None:
    """Warn (:class:`ReplacedWhileRunning`) when ``target`` was written by another process
    after this one first checked it."""
    marker = _read_marker(target)
    if not marker:
        return
    pid, written = marker.get("pid"), marker.get("time")
    if pid == os.getpid() or not isinstance(written, (int, float)) or written < _checked_at(target):
        return
    warnings.warn(
        f"--out {directory}: replaced the {marker.get('kind', 'output')} folder that process {pid} wrote "
        "while this one ran (the last writer wins)",
        ReplacedWhileRunning,
        stacklevel=3,
    )


def _swap_into_place(staging: Path, target: Path, directory: str | os.PathLike[str]) -> Path | None:
    """Replace ``target`` by ``staging`` (same parent folder) with two renames (the caller
    holds signals back); returns where the old folder went (to be removed), None if there was
    none. A failed second rename puts the old folder back; if even that fails, the error says
    where it is."""
    old: Path | None = None
    if os.path.lexists(target):
        old = target.parent / staging_name(target.name, "old")
        os.rename(target, old)
    try:
        os.rename(staging, target)
    except OSError:
        if old is not None:
            try:
                os.rename(old, target)
            except OSError as exc:
                raise OutputError(
                    f"--out {directory}: cannot replace it, nor put the old folder back ({exc.strerror or exc}); "
                    f"it is kept as {old}"
                ) from None
        raise
    return old


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
