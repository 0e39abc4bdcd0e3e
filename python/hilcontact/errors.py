"""Exceptions raised by hilcontact.

The classes are defined once, in the native bindings (``hilcontact._core``), which raise them
directly; this module is their public home (and that of :class:`ArgumentError`, the Python
API's own):

- :class:`HilContactError`: base class of every error raised on purpose by hilcontact;
- :class:`ScenarioError` (also a ``ValueError``): a scenario (file, preset name, override or
  value) is invalid; the message is a single line naming the first offending key as a dotted
  path (``servicer.mass``, ``walls[0].normal``) and what is allowed, and ``issues`` (where
  set) lists every problem as ``(key, message)``;
- :class:`ArgumentError` (a ``ScenarioError``, so also a ``ValueError``): an argument of a
  function of the Python API has a type or value it does not take (``threads='x'``,
  ``compare(scenario, 5)``, overrides given as a list, a missing optional package such as
  dask); the message is one line starting with the argument's name;
- :class:`RealtimeError` (also an ``OSError``): the real-time runtime or the emulated
  facility could not start or finish (a port in use, a peer that does not answer, a bad
  ``/netftapi2.xml``); for an error of the OS, ``errno`` (e.g. ``errno.EADDRINUSE``) and
  ``strerror`` are set and ``kind`` names the Rust ``std::io::ErrorKind`` (``"AddrInUse"``),
  otherwise ``errno`` is None;
- :class:`RealtimeOptionError` (a ``RealtimeError`` and a ``ValueError``): a real-time
  option (limit, port, mapping) is invalid; the message names it.

Output folders have their own, :class:`hilcontact.output.OutputError` (a ``HilContactError``
and a ``ValueError``).
"""

from __future__ import annotations

from ._core import HilContactError, RealtimeError, RealtimeOptionError, ScenarioError

__all__ = ["ArgumentError", "HilContactError", "RealtimeError", "RealtimeOptionError", "ScenarioError"]


class ArgumentError(ScenarioError):
    """A bad argument of a function of the Python API: a type or value it does not take. The
    message is one line starting with the argument's name (``threads: expected a whole number
    from 1 to 1024, got 'x'``). A ``ScenarioError``, hence a ``ValueError``: the command line
    reports it as bad input (exit code 2)."""


def describe(value: object, limit: int = 60) -> str:
    """A short rendering of a user's value for a message (never fails, never long: a huge
    integer is named by its number of digits)."""
    try:
        text = repr(value)
    except ValueError:  # an integer above Python's limit on digits
        text = f"an integer of about {int(value.bit_length() * 0.30103) + 1} digits" if isinstance(value, int) else "a value"
    except Exception:  # a user's object whose repr fails
        text = f"a {type(value).__name__}"
    return text if len(text) <= limit else text[: limit - 3] + "..."
