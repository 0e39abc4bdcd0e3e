"""Exceptions raised by hilcontact.

The classes are defined once, in the native bindings (``hilcontact._core``), which raise them
directly; this module is their public home:

- :class:`HilContactError`: base class of every error raised on purpose by hilcontact;
- :class:`ScenarioError` (also a ``ValueError``): a scenario (file, preset name, override or
  value) is invalid; the message is a single line naming the first offending key as a dotted
  path (``servicer.mass``, ``walls[0].normal``) and what is allowed, and ``issues`` (where
  set) lists every problem as ``(key, message)``;
- :class:`RealtimeError` (also an ``OSError``): the real-time runtime or the emulated
  facility could not start or finish (a port in use, a peer that does not answer, a bad
  ``/netftapi2.xml``); for an error of the OS, ``errno`` (e.g. ``errno.EADDRINUSE``) and
  ``strerror`` are set and ``kind`` names the Rust ``std::io::ErrorKind`` (``"AddrInUse"``),
  otherwise ``errno`` is None;
- :class:`RealtimeOptionError` (a ``RealtimeError`` and a ``ValueError``): a real-time
  option (limit, port, mapping) is invalid; the message names it.
"""

from __future__ import annotations

from ._core import HilContactError, RealtimeError, RealtimeOptionError, ScenarioError

__all__ = ["HilContactError", "RealtimeError", "RealtimeOptionError", "ScenarioError"]
