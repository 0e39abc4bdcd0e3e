"""Exceptions raised by hilcontact.

The native core (``hilcontact._core``) imports :class:`ScenarioError` from this module and
raises it for invalid scenarios that slip past the Python validation, so keep the names and
the module path stable.
"""

from __future__ import annotations

__all__ = ["HilContactError", "RealtimeError", "RealtimeOptionError", "ScenarioError"]


class HilContactError(Exception):
    """Base class of every error raised on purpose by hilcontact."""


class ScenarioError(HilContactError, ValueError):
    """A scenario (file, preset name, override or value) is invalid.

    The message is a single line that names the offending key as a dotted path
    (``servicer.mass``, ``walls[0].normal``) and says what is allowed.
    """


class RealtimeError(HilContactError):
    """The real-time runtime or the emulated facility could not start or finish: a port in
    use, a peer that does not answer (sensor, robot), a bad ``/netftapi2.xml``."""


class RealtimeOptionError(RealtimeError, ValueError):
    """A real-time option (limit, port, mapping) is invalid; the message names it."""
