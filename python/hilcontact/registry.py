"""The compensator registry, read from the core: the one list of compensator kinds, with
each kind's one-line summary, plot colour and default parameters.

Adding a compensator to the core's registry (``crates/core/src/compensator/mod.rs``) makes
it known here; nothing in Python lists the kinds again.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from . import _core

__all__ = ["COMPENSATORS", "KINDS", "CompensatorInfo"]


@dataclass(frozen=True)
class CompensatorInfo:
    """One registered compensator kind."""

    kind: str
    """The ``kind`` string of ``[compensator]``."""
    summary: str
    """One line for humans."""
    colour: str
    """Plot colour (a matplotlib colour name)."""
    defaults: dict[str, Any]
    """Its ``[compensator]`` table with default parameters (``kind`` included)."""


COMPENSATORS: dict[str, CompensatorInfo] = {
    entry["kind"]: CompensatorInfo(**entry) for entry in json.loads(_core.compensator_registry())
}
"""Every registered compensator, in the registry's order."""

KINDS: tuple[str, ...] = tuple(COMPENSATORS)
"""Every registered compensator kind, in the registry's order."""
