"""Resource limits: a run, a comparison or a sweep whose memory or time estimate is above a
limit is refused before anything runs, with one line that states the estimate and the limit
(:class:`~hilcontact.errors.ScenarioError`, exit code 2 on the command line).

The estimates are simple and on the safe side: a run keeps one row per control period (the
HIL loop, the ideal reference and their metric traces), and takes a time per control period
that grows with ``simulation.plant_substeps`` and ``simulation.reference_substeps`` (every
period counted as if in contact). The constants below were measured on paper-table1.
Raise a limit with ``--max-memory`` / ``--max-time`` (or :class:`Limits` from Python).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

from .errors import ScenarioError

__all__ = ["DEFAULT_LIMITS", "Estimate", "Limits", "check_estimate", "run_estimate"]

#: Memory a saved run takes per control period, bytes (time series, reference, traces, the
#: data frames and the Parquet files being written).
RUN_BYTES_PER_TICK = 1000.0  # measured: about 850
#: Memory a sweep's run takes per control period while it runs, bytes (its metric traces).
SUMMARY_BYTES_PER_TICK = 400.0
#: Memory a sweep keeps per run once planned, bytes (its resolved scenario, its result row).
SWEEP_BYTES_PER_RUN = 20_000.0
#: Time of one control period of a run, s: the HIL tick and the reference's free-flight step,
#: then per plant sub-step and per reference sub-step.
SECONDS_PER_TICK = 4e-6
SECONDS_PER_PLANT_SUBSTEP = 0.3e-6
SECONDS_PER_REFERENCE_SUBSTEP = 1e-6
#: Time to validate one run of a sweep before it starts, s.
SWEEP_SECONDS_PER_RUN = 2e-3


@dataclass(frozen=True)
class Limits:
    """The largest memory (GB) and time (s) a command may be estimated to need."""

    max_memory: float = 2.0
    max_time: float = 3600.0

    def __post_init__(self) -> None:
        for name, option in (("max_memory", "--max-memory"), ("max_time", "--max-time")):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
                raise ScenarioError(f"{option}: must be a finite number > 0, got {value!r}")


#: The limits of a command that is given no other.
DEFAULT_LIMITS = Limits()


@dataclass(frozen=True)
class Estimate:
    """What something is estimated to need: memory (bytes) and time (s, on one core)."""

    memory: float
    time: float

    def scaled(self, memory: float = 1.0, time: float = 1.0) -> Estimate:
        return Estimate(self.memory * memory, self.time * time)


def ticks(scenario: Any) -> float:
    """Control periods of a run (``duration / period``, plus the initial one)."""
    sim = scenario.simulation
    return sim.duration / sim.period + 1.0


def seconds_per_tick(scenario: Any) -> float:
    sim = scenario.simulation
    return (
        SECONDS_PER_TICK
        + SECONDS_PER_PLANT_SUBSTEP * sim.plant_substeps
        + SECONDS_PER_REFERENCE_SUBSTEP * sim.reference_substeps
    )


def run_estimate(scenario: Any, saved: bool = True) -> Estimate:
    """A run's estimate; ``saved=False``: a sweep's run, reduced to its summary row."""
    n = ticks(scenario)
    return Estimate(n * (RUN_BYTES_PER_TICK if saved else SUMMARY_BYTES_PER_TICK), n * seconds_per_tick(scenario))


def describe(scenario: Any) -> str:
    """The keys an estimate comes from, for the message."""
    sim = scenario.simulation
    return (
        f"simulation.duration = {sim.duration:g} s at simulation.period = {sim.period:g} s "
        f"({ticks(scenario):.3g} control periods, {sim.plant_substeps} plant and "
        f"{sim.reference_substeps} reference sub-steps each)"
    )


def _size(memory: float) -> str:
    gb = memory / 1e9
    return f"{gb:.3g} GB" if gb < 1000 else f"{gb / 1000:.3g} TB"


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.3g} s"
    if seconds < 7200:
        return f"{seconds / 60:.3g} min"
    return f"{seconds / 3600:.3g} h"


def check_estimate(estimate: Estimate, limits: Limits | None, what: str) -> None:
    """Raise ScenarioError (one line) if ``estimate`` is above ``limits``; ``what`` says what
    it is the estimate of (``"the run of simulation.duration = ..."``)."""
    limits = limits or DEFAULT_LIMITS
    if not estimate.memory <= limits.max_memory * 1e9:
        raise ScenarioError(
            f"{what} needs about {_size(estimate.memory)} of memory, above the limit of "
            f"{limits.max_memory:g} GB: make it smaller, or raise the limit with --max-memory GB"
        )
    if not estimate.time <= limits.max_time:
        raise ScenarioError(
            f"{what} takes about {_duration(estimate.time)} on one core, above the limit of "
            f"{limits.max_time:g} s: make it smaller, or raise the limit with --max-time S"
        )


def check_run(scenario: Any, limits: Limits | None, runs: int = 1) -> None:
    """Refuse ``runs`` saved runs of ``scenario`` (a run: 1, a comparison: one per
    compensator, all held in memory) above ``limits``."""
    what = f"{'the run' if runs == 1 else f'{runs} runs'} of {describe(scenario)}"
    check_estimate(run_estimate(scenario).scaled(memory=runs, time=runs), limits, what)


def cores() -> int:
    return os.cpu_count() or 1
