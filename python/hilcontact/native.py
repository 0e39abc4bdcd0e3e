"""The native core, ``hilcontact._core`` (the Rust extension), behind one accessor that says
how to build it when it is missing, and the package's version. A leaf module: it imports
nothing of the package but :mod:`hilcontact.errors`, so that every other module may use it."""

from __future__ import annotations

from importlib import metadata as _metadata
from typing import Any

from .errors import HilContactError

__all__ = ["VERSION", "core", "core_version"]

try:
    #: The installed package's version (``0+unknown`` in a source tree that was never installed).
    VERSION = _metadata.version("hilcontact")
except _metadata.PackageNotFoundError:  # pragma: no cover - running from a source tree
    VERSION = "0+unknown"


def core() -> Any:
    """The native module ``hilcontact._core``; raises
    :class:`~hilcontact.errors.HilContactError` saying how to build it when it is not there."""
    try:
        from . import _core as native
    except ImportError as exc:
        raise HilContactError(
            "the native extension hilcontact._core is not available; build it with "
            f"`pip install .` or `maturin develop --release` ({exc})"
        ) from None
    return native


def core_version() -> str | None:
    """Version of the native core, or None if it is not built."""
    try:
        return str(core().version())
    except HilContactError:
        return None
