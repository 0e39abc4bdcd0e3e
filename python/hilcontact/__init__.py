"""hilcontact: hardware-in-the-loop simulation of satellite contact.

A robot reproduces the relative motion of two satellites, a force sensor measures the real
contact, and the delay of the loop makes collisions rebound faster than they should. This
package simulates that loop (facility model, compensators, ideal reference) through its
Rust core ``hilcontact._core``.

Quick start::

    import hilcontact as hc
    scenario = hc.load_scenario("paper-table1", {"facility.robot_delay": 0.02})
    run = hc.simulate(scenario)
    print(run.status, run.collision_table())
    run.save("runs/paper-table1-20ms")
    hc.compare("paper-table1", overrides={"facility.robot_delay": 0.02}).summary
    rows = hc.sweep("paper-table1", {"facility.robot_delay": "0.002:0.06:30"}, "none,pida")
    hc.stability_map(rows).max_faithful_delay()

Real time (see ``hilcontact.realtime``): ``hc.start_facility(scenario, options)`` runs the
emulated facility (ATI Net F/T RDT sensor, ABB EGM robot) and ``hc.run_hil(scenario, options)``
runs the HIL loop against it or against a real facility.

Conventions: SI units (m, s, N, N m, kg, rad); points and normals of the collision frame in
the target mockup frame ``t``; quaternions ``[w, x, y, z]``.
"""

from __future__ import annotations

from ._startup import guard as _guard

_guard()  # the `hilcontact` command: Ctrl-C while importing is one line, exit 130 (hilcontact._startup)

from .comparison import Comparison, compare
from .errors import HilContactError, RealtimeError, RealtimeOptionError, ScenarioError
from .native import VERSION as __version__
from .plugin import Compensator, PluginError
from .realtime import Facility, run_hil, start_facility
from .run import Run, RunInterrupted, simulate
from .scenario import Scenario, apply_overrides, load_scenario, presets
from .stability import StabilityMap, stability_map
from .sweep import load_results, sweep

__all__ = [
    "Comparison",
    "Compensator",
    "PluginError",
    "Facility",
    "HilContactError",
    "RealtimeError",
    "RealtimeOptionError",
    "Run",
    "RunInterrupted",
    "Scenario",
    "ScenarioError",
    "StabilityMap",
    "__version__",
    "apply_overrides",
    "compare",
    "load_results",
    "load_scenario",
    "presets",
    "run_hil",
    "simulate",
    "stability_map",
    "start_facility",
    "sweep",
]
