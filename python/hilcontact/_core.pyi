"""Type stubs of the native extension ``hilcontact._core`` (built from crates/py by maturin).

Conventions: SI units (m, s, N, N m, kg, J); the rod-tip motion is the virtual relative
motion in the target mockup frame ``t``; measured/applied wrenches are the wrench on the
frame, in the sensor frame ``s``, about the sensor origin.
"""

from typing import Any

def simulate(scenario_json: str) -> dict[str, Any]:
    """Run one HIL simulation and its ideal reference.

    ``scenario_json`` is the fully resolved scenario as JSON (``Scenario.to_json()``).
    Returns ``{"timeseries": {column: float64 array}, "reference": {column: float64 array},
    "metrics": str}`` where ``metrics`` is JSON text.

    timeseries columns: ``time``, ``tip_position_{x,y,z}``, ``tip_velocity_{x,y,z}``,
    ``actual_tip_position_{x,y,z}``, ``actual_tip_velocity_{x,y,z}``,
    ``contact_force_{x,y,z}``, ``measured_force_{x,y,z}``, ``measured_moment_{x,y,z}``,
    ``applied_force_{x,y,z}``, ``applied_moment_{x,y,z}``, ``energy`` and, when the
    compensator estimates them, ``stiffness_estimate``, ``damping_estimate`` (N/m, N s/m),
    and, when it has an energy observer, ``observed_energy`` (J, NaN where not observed).

    reference columns: ``time``, ``tip_position_*``, ``tip_velocity_*``,
    ``contact_force_*``, ``energy``.

    metrics: ``{"scenario", "compensator", "status": "ok"|"diverged", "diverged_at",
    "reason", "collisions": [{"index", "start", "end", "peak_force", "rebound_speed",
    "cov", "cof"}], "reference_collisions": [...], "identification": {"stiffness_error",
    "damping_error"} | null, "energy": {"initial", "final", "reference_final", "max"},
    "summary": {"collisions", "mean_cov", "worst_cov", "mean_cof", "worst_cof"}}`` (worst:
    the value farthest from 1; null where there is none).

    Raises ``hilcontact.errors.ScenarioError`` for an invalid scenario.
    """

def simulate_batch(scenarios: list[str], threads: int | None = None) -> dict[str, Any]:
    """Run many scenarios (resolved JSON each) in parallel on Rust threads, the GIL released,
    keeping only each run's summary. ``threads``: pool size (default: one per core).

    Returns columns, one value per scenario in order: ``status`` (list of "ok"/"diverged")
    and float64 arrays ``diverged_at`` (s), ``collisions``, ``reference_collisions``,
    ``mean_cov``, ``worst_cov``, ``mean_cof``, ``worst_cof``, ``stiffness_error`` (fraction),
    ``damping_error`` (N s/m), ``energy_ratio`` (final / reference final), ``wall_time`` (s);
    NaN where a run has no such value. Raises ScenarioError for an invalid scenario.
    """

def version() -> str:
    """Version of the native core."""


def compensator_defaults() -> str:
    """The core's default parameters of every compensator kind, as JSON text:
    ``{kind: {"kind": kind, parameter: default, ...}}``."""
