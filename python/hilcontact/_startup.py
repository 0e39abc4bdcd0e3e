"""Ctrl-C while the ``hilcontact`` command starts: importing the package (pandas, pydantic,
the native core) takes a few tenths of a second, before the command line can catch anything.
In a ``hilcontact`` process (the console script or ``python -m hilcontact``) a Ctrl-C or
SIGTERM then prints one line and exits with code 130 (nothing has been written yet);
:func:`started` gives Ctrl-C back to Python (``KeyboardInterrupt``) once the command line
runs. Elsewhere (the package imported as a library) nothing changes. Imports nothing of the
package, so that it can come first."""

from __future__ import annotations

import os
import signal
import sys
import threading
from typing import Any

__all__ = ["finishing", "guard", "is_command", "started"]

#: The line printed when the command is stopped while it starts.
LINE = b"interrupted: stopped while starting; nothing written\n"


def is_command() -> bool:
    """Whether this process is the ``hilcontact`` command (console script or ``-m``)."""
    if sys.argv and os.path.basename(sys.argv[0]) == "hilcontact":
        return True
    argv = list(getattr(sys, "orig_argv", []))
    return "-m" in argv[:-1] and argv[argv.index("-m") + 1] == "hilcontact"


def _quit(_signum: int, _frame: Any) -> None:
    os.write(2, LINE)
    os._exit(130)


def guard() -> None:
    """In the ``hilcontact`` command's main thread, while Python's own Ctrl-C handler is in
    place: a Ctrl-C or SIGTERM from now until :func:`started` prints :data:`LINE` and exits
    with code 130."""
    if not is_command() or threading.current_thread() is not threading.main_thread():
        return
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _quit)
    if signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _quit)


def started() -> None:
    """The command line runs: Ctrl-C raises ``KeyboardInterrupt`` again (and SIGTERM gets its
    default back, until a command sets its own)."""
    if threading.current_thread() is not threading.main_thread():
        return
    if signal.getsignal(signal.SIGINT) is _quit:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if signal.getsignal(signal.SIGTERM) is _quit:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def finishing() -> None:
    """The command has done its work and exits: in the ``hilcontact`` command's main thread, a
    Ctrl-C or SIGTERM from now on is ignored. (Python's finalisation puts the default handlers
    back, and a signal landing there would end a finished command as killed, exit -2.)"""
    if not is_command() or threading.current_thread() is not threading.main_thread():
        return
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
