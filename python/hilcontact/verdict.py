"""What a run's metrics say against its scenario's ``[metrics]`` tolerances, collision by
collision: the broken tolerances (:class:`Violation`), from which collision on the run is
faithful, and its worst margin. Read by the comparison's ranking (:mod:`hilcontact.comparison`)
and the comparison figures' panel titles (:mod:`hilcontact.plots`); the core's own verdict
(``metrics["violations"]``, ``status``) is the reference these agree with (tests/test_compare.py)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .run import Run

__all__ = ["RENDERING_LABELS", "Violation", "rendering_label"]

#: How a collision was handled, ``metrics.json``'s per-collision key ``rendering`` (reported
#: by ``model-mediated``: rendered from its model, or handled by ``pida`` and why; none for the
#: other compensators), and its label in the tables.
RENDERING_LABELS: dict[str, str] = {
    "model": "model",
    "pida-no-prior": "pida: no prior",
    "pida-prior-contradicted": "pida: prior contradicted",
    "pida-law-unknown": "pida: law unknown",
}


def rendering_label(value: Any) -> str:
    """The table label of a collision's ``rendering`` value (``-`` when none is reported)."""
    return RENDERING_LABELS.get(value, "-") if isinstance(value, str) else "-"


@dataclass(frozen=True)
class Violation:
    """One tolerance a run broke: which collision (None: lost or extra collisions), which
    metric, its value and the limit of the scenario's ``[metrics]``."""

    collision: int | None
    metric: str  # "|CoV − 1|", "CoF", "velocity error (%)", "tangential impulse error (%)",
    # "lost collisions", "extra collisions"
    value: float
    limit: float

    def __str__(self) -> str:
        if self.collision is None:
            return f"{self.metric} {self.value:g} > {self.limit:g}"
        if self.metric.endswith(" (%)"):
            return f"collision {self.collision}: {self.metric[:-4]} {self.value:.2f} % > {self.limit:g} %"
        return f"collision {self.collision}: {self.metric} {self.value:.3f} > {self.limit:g}"


def _ratio(value: float, limit: float) -> float:
    if limit > 0:
        return value / limit
    return math.inf if value > 0 else 0.0


def _judge(run: Run) -> tuple[int | None, float, list[Violation]]:
    """(faithful_from, margin, violations) of a run against its scenario's ``[metrics]``."""
    tol = run.scenario.metrics
    collisions = [c for c in run.metrics.get("collisions") or [] if _finite(c.get("cov"))]
    violations: list[Violation] = []
    margins: dict[int, float] = {}
    for c in collisions:
        n = int(c["index"])
        if n < tol.judge_from:
            continue
        cov_error = abs(float(c["cov"]) - 1.0)
        cof = float(c["cof"]) if _finite(c.get("cof")) else 0.0
        v_error = float(c["velocity_error"]) if _finite(c.get("velocity_error")) else 0.0
        jt_error = float(c["tangential_impulse_error"]) if _finite(c.get("tangential_impulse_error")) else 0.0
        jt_limit = float(tol.max_tangential_impulse_error)
        margins[n] = max(_ratio(cov_error, tol.cov_tolerance), _ratio(cof, tol.max_cof),
                         _ratio(v_error, tol.max_velocity_error), _ratio(jt_error, jt_limit))
        if cov_error > tol.cov_tolerance:
            violations.append(Violation(n, "|CoV − 1|", cov_error, tol.cov_tolerance))
        if cof > tol.max_cof:
            violations.append(Violation(n, "CoF", cof, tol.max_cof))
        if v_error > tol.max_velocity_error:
            violations.append(Violation(n, "velocity error (%)", 100.0 * v_error, 100.0 * tol.max_velocity_error))
        if jt_error > jt_limit:
            violations.append(Violation(n, "tangential impulse error (%)", 100.0 * jt_error, 100.0 * jt_limit))
    counted = True
    for key, limit, name in (("lost_collisions", tol.max_lost_collisions, "lost collisions"),
                             ("extra_collisions", tol.max_extra_collisions, "extra collisions")):
        count = len(run.metrics.get(key) or [])
        if count > limit:
            violations.append(Violation(None, name, count, limit))
            counted = False
    start = max([tol.judge_from] + [v.collision + 1 for v in violations if v.collision is not None])
    later = [m for n, m in margins.items() if n >= start]
    if run.status in ("ok", "unfaithful") and counted and later:
        return start, max(later), violations
    return None, max(margins.values(), default=math.nan), violations


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
