"""Work shared between this process and one forked child: the figures of a comparison are
drawn on two cores this way (matplotlib draws on one). Closures are fine (nothing is pickled:
the child is a fork), and the child reports by its exit code only, leaving its results where
the parent finds them (files)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

__all__ = ["in_two_processes"]


def in_two_processes(items: Sequence[str], work: Callable[[list[str]], list[str]],
                     done_by_child: Callable[[str], bool]) -> list[str]:
    """Call ``work`` on ``items``, every other one (from the second) in a forked child process
    when the machine has two cores or more and the OS forks; ``work`` returns the items it did.
    A child that fails leaves its items to this process, which then does them itself (nothing
    is lost). Returns the items done, in the order of ``items``: those ``work`` returned here
    and the child's for which ``done_by_child`` is true."""
    items = list(items)
    child_items = items[1::2] if len(items) > 1 and (os.cpu_count() or 1) > 1 and hasattr(os, "fork") else []
    pid = os.fork() if child_items else -1
    if pid == 0:  # the child: do its half, report by exit code only, never return
        code = 1
        try:
            work(child_items)
            code = 0
        finally:
            os._exit(code)
    mine = work([i for i in items if i not in child_items])
    if pid > 0:
        _, status = os.waitpid(pid, 0)
        if not (os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0):
            mine += work(child_items)  # the child failed: do its items here
    return [i for i in items if i in mine or (i in child_items and done_by_child(i))]
