"""MuJoCo as an independent engine (docs/mujoco.md): the MJCF writer (:mod:`.mjcf`), the
cross-check of the ideal reference against MuJoCo (:mod:`.crosscheck`) and the facility engine
``facility.kind = "mujoco"`` (:mod:`.facility`). Needs the optional ``mujoco`` package
(``pip install 'hilcontact[mujoco]'``); :func:`require` says so in one line when it is missing.
"""

from __future__ import annotations

from typing import Any

from ..errors import ArgumentError

__all__ = ["INSTALL_HINT", "require"]

#: How to install the optional package.
INSTALL_HINT = "pip install 'hilcontact[mujoco]'"


def require(what: str = "facility.kind = \"mujoco\"") -> Any:
    """The ``mujoco`` module; raises :class:`~hilcontact.errors.ArgumentError` (bad input, exit
    code 2 on the command line) naming ``what`` needs it when it is not installed."""
    try:
        import mujoco
    except ImportError:
        raise ArgumentError(f"{what}: needs the mujoco package, which is not installed: {INSTALL_HINT}") from None
    return mujoco
