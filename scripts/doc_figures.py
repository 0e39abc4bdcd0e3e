#!/usr/bin/env python3
"""The numbers the docs quote, computed by running the simulations they come from.

Each figure is a region of a Markdown page between ``<!-- doc-figures: NAME -->`` and
``<!-- /doc-figures -->`` (invisible when the page is rendered), and a function below that
writes the region's text from fresh runs. ``--check`` (what tests/test_doc_figures.py runs)
fails when a page differs; ``--write`` updates the pages.

    python scripts/doc_figures.py            # print every figure
    python scripts/doc_figures.py --check    # exit 1 and show the differences if a page is stale
    python scripts/doc_figures.py --write    # update the pages

Every run is deterministic (fixed seeds), so the text is reproducible to the last digit.
"""

from __future__ import annotations

import argparse
import difflib
import json
import re
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import hilcontact as hc

ROOT = Path(__file__).resolve().parents[1]

#: The noisy case of the compensator pages: 20 ms robot delay, 5 ms sensor delay, 0.2 N noise.
NOISY = {"facility.robot_delay": 0.02, "facility.sensor_delay": 0.005, "facility.sensor_noise": 0.2}

#: The rows of the compensator tables: (label, preset, overrides).
CASES: list[tuple[str, str, dict[str, Any]]] = [
    ("`paper-table1`, 10 ms", "paper-table1", {}),
    ("20 ms", "paper-table1", {"facility.robot_delay": 0.02}),
    ("40 ms", "paper-table1", {"facility.robot_delay": 0.04}),
    ("60 ms", "paper-table1", {"facility.robot_delay": 0.06}),
    ("noisy", "paper-table1", NOISY),
    ("noisy, `--set compensator.delay_mode=lead`", "paper-table1", {**NOISY, "compensator.delay_mode": "lead"}),
    ("`paper-exp-2.64hz`", "paper-exp-2.64hz", {}),
    ("`paper-exp-1.93hz`", "paper-exp-1.93hz", {}),
]

_CACHE: dict[tuple[str, str, str], hc.Run] = {}


def run(preset: str, kind: str, overrides: Mapping[str, Any] | None = None) -> hc.Run:
    """The run of ``preset`` with ``compensator.kind = kind`` and the overrides (cached)."""
    items = dict(overrides or {})
    key = (preset, kind, json.dumps(items, sort_keys=True))
    if key not in _CACHE:
        _CACHE[key] = hc.simulate(hc.load_scenario(preset, {**items, "compensator.kind": kind}))
    return _CACHE[key]


def covs(r: hc.Run) -> str:
    """The CoV of each collision, 3 decimals."""
    return ", ".join(f"{c['cov']:.3f}" for c in r.metrics["collisions"] if c.get("cov") is not None)


def worst_cof(r: hc.Run) -> str:
    value = r.metrics["summary"].get("worst_cof")
    return "-" if value is None else f"{value:.3f}"


def first_cof(r: hc.Run) -> str:
    collisions = [c for c in r.metrics["collisions"] if c.get("cof") is not None]
    return f"{collisions[0]['cof']:.3f}" if collisions else "-"


def dac_table() -> str:
    lines = ["| case | CoV per collision | worst CoF | `none`, first CoF |", "|---|---|--:|--:|"]
    for label, preset, overrides in CASES:
        lead = overrides.get("compensator.delay_mode") == "lead"
        none = "" if lead else first_cof(run(preset, "none", overrides))
        r = run(preset, "dac", overrides)
        lines.append(f"| {label} | {covs(r)} | {worst_cof(r)} | {none} |")
    return "\n".join(lines)


def pida_table() -> str:
    lines = ["| case | CoV per collision | worst CoF | k error (%) | c error (N·s/m) |", "|---|---|--:|--:|--:|"]
    for label, preset, overrides in CASES:
        r = run(preset, "pida", overrides)
        identification = r.metrics.get("identification") or {}
        k = identification.get("stiffness_error")
        c = identification.get("damping_error")
        k_text = "-" if k is None else f"{100 * k:.3g}"
        c_text = "-" if c is None else f"{c:.3g}"
        lines.append(f"| {label} | {covs(r)} | {worst_cof(r)} | {k_text} | {c_text} |")
    return "\n".join(lines)


def lead_table() -> str:
    """`align` against `lead` on the noisy case, per compensator that has `delay_mode`."""
    lines = [
        "| compensator | `align`: CoV per collision | `align`: worst CoF | `lead`: CoV per collision | `lead`: worst CoF |",
        "|---|---|--:|---|--:|",
    ]
    for kind in ("pic", "dac", "pida"):
        align = run("paper-table1", kind, NOISY)
        lead = run("paper-table1", kind, {**NOISY, "compensator.delay_mode": "lead"})
        lines.append(f"| `{kind}` | {covs(align)} | {worst_cof(align)} | {covs(lead)} | {worst_cof(lead)} |")
    return "\n".join(lines)


def zero_delay() -> str:
    """The no-delay loop against the ideal reference on paper-table1: CoV and CoF ranges."""
    r = run("paper-table1", "none", {"facility.robot_delay": 0.0})
    cov = [c["cov"] for c in r.metrics["collisions"]]
    cof = [c["cof"] for c in r.metrics["collisions"]]
    return (
        f"CoV {min(cov):.7f}–{max(cov):.7f} and CoF {min(cof):.6f}–{max(cof):.6f} on all "
        f"{len(cov)} collisions of `paper-table1`"
    )


#: The cases without the `lead` row (the compensators without `delay_mode`, and pic's table).
PLAIN_CASES = [case for case in CASES if "compensator.delay_mode" not in case[2]]


def cov_range(r: hc.Run) -> str:
    """The CoV of the collisions as a range, 3 decimals: ``1.001-1.005``, or ``1.000 ×5``."""
    values = [f"{c['cov']:.3f}" for c in r.metrics["collisions"] if c.get("cov") is not None]
    if not values:
        return "-"
    low, high = min(values, key=float), max(values, key=float)
    return f"{low} ×{len(values)}" if low == high else f"{low}-{high}"


def status(r: hc.Run) -> str:
    at = r.metrics.get("diverged_at")
    return f"{r.status} at {at:.3f} s" if r.status == "diverged" and at is not None else r.status


def pic_table() -> str:
    lines = ["| case | status | CoV per collision | worst CoF | k error (%) |", "|---|---|---|--:|--:|"]
    for label, preset, overrides in PLAIN_CASES:
        r = run(preset, "pic", overrides)
        k = (r.metrics.get("identification") or {}).get("stiffness_error")
        lines.append(f"| {label} | {status(r)} | {covs(r)} | {worst_cof(r)} | {'-' if k is None else f'{100 * k:.3g}'} |")
    return "\n".join(lines)


def tdpa_impedance_table() -> str:
    lines = ["| case | `tdpa-impedance` CoV per collision | worst CoF | `dac` CoV | `pida` CoV (worst CoF) |",
             "|---|---|--:|---|---|"]
    for label, preset, overrides in PLAIN_CASES:
        r, dac, pida = (run(preset, kind, overrides) for kind in ("tdpa-impedance", "dac", "pida"))
        lines.append(f"| {label} | {covs(r)} | {worst_cof(r)} | {cov_range(dac)} | {cov_range(pida)} ({worst_cof(pida)}) |")
    return "\n".join(lines)


def tdpa_admittance_table() -> str:
    lines = ["| case | `tdpa-admittance` CoV per collision | worst CoF | `pida` CoV (worst CoF) |", "|---|---|--:|---|"]
    for label, preset, overrides in PLAIN_CASES:
        r, pida = run(preset, "tdpa-admittance", overrides), run(preset, "pida", overrides)
        lines.append(f"| {label} | {covs(r)} | {worst_cof(r)} | {cov_range(pida)} ({worst_cof(pida)}) |")
    return "\n".join(lines)


def cov_cell(r: hc.Run) -> str:
    """A compact CoV cell with the worst CoF: the list when the CoV moves by more than half a
    per cent over the run, else the range."""
    values = [c["cov"] for c in r.metrics["collisions"] if c.get("cov") is not None]
    spread = max(values) - min(values) if values else 0.0
    return f"{covs(r) if spread > 0.005 else cov_range(r)} ({worst_cof(r)})"


def energy_table() -> str:
    """`work` against the paper's observer, for dac and pida."""
    lines = ["| case | `dac`, `work` | `dac`, `paper` | `pida`, `work` | `pida`, `paper` |", "|---|---|---|---|---|"]
    for label, preset, overrides in [("10 ms", "paper-table1", {}), ("20 ms", "paper-table1", {"facility.robot_delay": 0.02}),
                                     ("`paper-exp-2.64hz`", "paper-exp-2.64hz", {})]:
        cells = [cov_cell(run(preset, kind, {**overrides, **observer}))
                 for kind in ("dac", "pida") for observer in ({}, {"compensator.observer": "paper"})]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def model_table() -> str:
    """The loop without compensation against the ideal reference."""
    lines = ["| case | collisions | CoV | CoF |", "|---|---|---|---|"]
    for label, preset, overrides in [("`paper-table1`, no delay", "paper-table1", {"facility.robot_delay": 0.0}),
                                     ("`paper-table1`, 10 ms, `none`", "paper-table1", {}),
                                     ("`paper-table1`, 20 ms, `none`", "paper-table1", {"facility.robot_delay": 0.02}),
                                     ("`oblique-6dof`, no delay", "oblique-6dof", {"facility.robot_delay": 0.0})]:
        r = run(preset, "none", overrides)
        done = [c for c in r.metrics["collisions"] if c.get("cov") is not None]
        cov = [c["cov"] for c in done]
        cof = [c["cof"] for c in done if c.get("cof") is not None]
        at = r.metrics.get("diverged_at")
        count = f"{len(done)}, then diverged at {at:.1f} s" if r.status == "diverged" and at is not None else f"{len(done)}"
        if max(cov) - 1.0 < 1e-4:
            cells = f"{min(cov):.6f} – {max(cov):.6f} | {min(cof):.6f} – {max(cof):.6f}"
        else:
            cells = f"{', '.join(f'{v:.2f}' for v in cov)} | {cof[0]:.2f} → {cof[-1]:.2f}"
        lines.append(f"| {label} | {count} | {cells} |")
    return "\n".join(lines)


def damping_at_04() -> str:
    """|ĉ − c| on `paper-exp-2.64hz` with 0.4 N noise, per identifying compensator."""
    errors = [run("paper-exp-2.64hz", kind, {"facility.sensor_noise": 0.4}).metrics["identification"]["damping_error"]
              for kind in ("pic", "dac", "pida")]
    return " / ".join(f"{abs(e):.1f}" for e in errors) + " N·s/m"


def with_prior(preset: str, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The overrides plus the scenario's own walls as `model-mediated`'s prior walls."""
    walls = hc.load_scenario(preset).to_dict()["walls"]
    return {**overrides, "compensator.prior_walls": walls}


#: The `model-mediated` page's rows: (label, preset, overrides, with a prior).
_HUNT = {"contact.model": "hunt-crossley", "contact.stiffness": 6.2e6, "contact.exponent": 1.5, "contact.damping": 3.1e7}
MODEL_MEDIATED_CASES: list[tuple[str, str, dict[str, Any], bool]] = [
    *[(f"`paper-table1`, {int(d * 1000)} ms", "paper-table1", {"facility.robot_delay": d}, False) for d in (0.02, 0.04, 0.08, 0.12)],
    *[(f"{int(d * 1000)} ms, noisy", "paper-table1",
       {"facility.robot_delay": d, "facility.sensor_delay": 0.005, "facility.sensor_noise": 0.2}, False) for d in (0.02, 0.04, 0.08, 0.12)],
    ("120 ms, prior", "paper-table1", {"facility.robot_delay": 0.12}, True),
    ("40 ms, 10 Hz servo lag", "paper-table1", {"facility.robot_delay": 0.04, "facility.servo_frequency": 10.0}, False),
    ("40 ms, 10 Hz servo lag, prior", "paper-table1", {"facility.robot_delay": 0.04, "facility.servo_frequency": 10.0}, True),
    ("40 ms, Hunt-Crossley", "paper-table1", {"facility.robot_delay": 0.04, **_HUNT}, False),
    ("40 ms, Hunt-Crossley, prior", "paper-table1", {"facility.robot_delay": 0.04, **_HUNT}, True),
    ("40 ms, ζ = 0.1", "paper-table1", {"facility.robot_delay": 0.04, "contact.damping": 1403.0}, False),
    ("40 ms, ζ = 0.1, prior", "paper-table1", {"facility.robot_delay": 0.04, "contact.damping": 1403.0}, True),
    ("`oblique-6dof`, 40 ms", "oblique-6dof", {"facility.robot_delay": 0.04}, False),
    ("`oblique-6dof`, 40 ms, prior", "oblique-6dof", {"facility.robot_delay": 0.04}, True),
]


def per_collision(r: hc.Run, key: str) -> str:
    """One metric of each collision, 3 decimals (``-`` where not compared)."""
    values = [c.get(key) for c in r.metrics["collisions"]]
    return ", ".join("-" if v is None else f"{v:.3f}" for v in values)


def model_mediated_table() -> str:
    """`model-mediated` against `pida` on the issue's cases, per collision."""
    lines = [
        "| case | CoV | CoF | velocity error | `pida` CoF | lost |",
        "|---|---|---|---|---|--:|",
    ]
    for label, preset, overrides, prior in MODEL_MEDIATED_CASES:
        r = run(preset, "model-mediated", with_prior(preset, overrides) if prior else overrides)
        p = run(preset, "pida", overrides)
        lost = len(r.metrics.get("lost_collisions") or [])
        lines.append(
            f"| {label} | {per_collision(r, 'cov')} | {per_collision(r, 'cof')} | "
            f"{per_collision(r, 'velocity_error')} | {per_collision(p, 'cof')} | {lost} |"
        )
    return "\n".join(lines)


def _faithful_from(r: hc.Run, first: int) -> bool:
    """Whether collisions ``first``… (1-based) keep the default tolerances, none lost, and at
    least one is compared."""
    if r.status == "diverged" or r.metrics.get("lost_collisions"):
        return False
    later = [c for c in r.metrics["collisions"][first - 1:] if c.get("cov") is not None]
    return bool(later) and all(
        abs(c["cov"] - 1) <= 0.05 and c["cof"] <= 1.2 and (c.get("velocity_error") or 0) <= 0.05 for c in later
    )


def _reach(kind: str, stiffness: float, first: int) -> str:
    """The largest robot delay (10-ms steps up to 200 ms) up to which every delay is faithful."""
    best = 0
    for ms in range(10, 201, 10):
        r = run("paper-table1", kind, {"facility.robot_delay": ms / 1000, "contact.stiffness": stiffness})
        if not _faithful_from(r, first):
            break
        best = ms
    return f"{best} ms" if best else "< 10 ms"


def model_mediated_reach() -> str:
    """How far each compensator stays faithful, per contact frequency (`paper-table1`)."""
    lines = [
        "| contact frequency | `pida`, every collision | `pida`, from collision 3 | `model-mediated`, from collision 3 |",
        "|---|--:|--:|--:|",
    ]
    for hz, factor in ((2, 0.25), (4, 1.0), (8, 4.0)):
        k = 176275.0 * factor
        lines.append(
            f"| {hz} Hz (k = {k / 1000:g} N/mm) | {_reach('pida', k, 1)} | {_reach('pida', k, 3)} | "
            f"{_reach('model-mediated', k, 3)} |"
        )
    return "\n".join(lines)


def readme_model_mediated() -> str:
    """The README's row: `model-mediated` on `paper-table1` at 40 and 120 ms."""
    cells = []
    for d in (0.04, 0.12):
        r = run("paper-table1", "model-mediated", {"facility.robot_delay": d})
        later = [c for c in r.metrics["collisions"][2:] if c.get("cof") is not None]
        worst = max(abs(c["cov"] - 1) for c in later)
        cof = max(c["cof"] for c in later)
        cells.append(f"{int(d * 1000)} ms: \\|CoV − 1\\| ≤ {worst:.3f}, CoF ≤ {cof:.3f}")
    return "; ".join(cells)


# ---- docs/choosing.md: which compensator for which delay, contact frequency and noise ----------

#: The sweep of docs/choosing.md: robot delays (s), contact stiffnesses (N/m) giving 2, 4 and
#: 8 Hz on `paper-table1`, force noise (N, std per axis), seeds per point, compensators.
CHOOSING_DELAYS = [0.01, 0.02, 0.04, 0.08]
CHOOSING_STIFFNESS = [44068.75, 176275.0, 705100.0]
CHOOSING_NOISE = [0.0, 0.3]
CHOOSING_SEEDS = 3
CHOOSING_KINDS = ["pic", "dac", "pida", "tdpa-impedance", "tdpa-admittance", "model-mediated"]

_SWEEPS: dict[str, Any] = {}


def choosing_sweeps() -> tuple[Any, Any]:
    """The sweep of every compensator judged on every collision, and `model-mediated`'s judged
    from collision 3 (each wall's second contact on `paper-table1`); cached."""
    if not _SWEEPS:
        grid = {"facility.robot_delay": CHOOSING_DELAYS, "contact.stiffness": CHOOSING_STIFFNESS,
                "facility.sensor_noise": CHOOSING_NOISE}
        _SWEEPS["all"] = hc.sweep("paper-table1", grid, compensators=CHOOSING_KINDS, seeds=CHOOSING_SEEDS)
        _SWEEPS["from3"] = hc.sweep("paper-table1", grid, compensators="model-mediated", seeds=CHOOSING_SEEDS,
                                    overrides={"metrics.judge_from": 3})
    return _SWEEPS["all"], _SWEEPS["from3"]


def _margin(rows: Any) -> float:
    """The worst margin of a cell's runs (as the comparison's ranking: the largest value /
    limit of |CoV − 1|, CoF and velocity error, default tolerances)."""
    return float(max((rows["worst_cov"] - 1.0).abs().max() / 0.05, rows["worst_cof"].max() / 1.2,
                     rows["worst_velocity_error"].max() / 0.05))


def choosing_table(noise: float) -> str:
    """Per contact frequency and robot delay: the compensators faithful by the stability map's
    cell rule (all seeds but at most one, fewer than half), best (smallest worst margin) first
    and in bold; then `model-mediated` if faithful only from collision 3."""
    from hilcontact.stability import stability_map

    rows, from3 = choosing_sweeps()
    rows, from3 = rows[rows["facility.sensor_noise"] == noise], from3[from3["facility.sensor_noise"] == noise]
    cells = stability_map(rows).cells.set_index(["compensator", "contact_frequency", "robot_delay"])
    cells3 = stability_map(from3).cells.set_index(["compensator", "contact_frequency", "robot_delay"])
    freqs = sorted(rows["contact_frequency"].unique())
    lines = ["| contact frequency | " + " | ".join(f"{d * 1e3:g} ms" for d in CHOOSING_DELAYS) + " |",
             "|---|" + "---|" * len(CHOOSING_DELAYS)]
    for freq in freqs:
        row = [f"{freq:.2f} Hz"]
        for delay in CHOOSING_DELAYS:
            ok = []
            for kind in CHOOSING_KINDS:
                cell = cells.loc[(kind, freq, delay)]
                if cell["faithful"]:
                    runs = rows[(rows["compensator"] == kind) & (rows["contact_frequency"] == freq) & (rows["robot_delay"] == delay)]
                    ok.append((_margin(runs), kind, int(cell["faithful_runs"]), int(cell["runs"])))
            ok.sort()
            text = [f"{'**' + kind + '**' if i == 0 else kind}" + ("" if good == runs else f" ({good}/{runs})")
                    for i, (_, kind, good, runs) in enumerate(ok)]
            later = cells3.loc[("model-mediated", freq, delay)]
            if "model-mediated" not in [k for _, k, _, _ in ok] and later["faithful"]:
                name = "model-mediated from #3"
                text.append(f"**{name}**" if not ok else name)
            row.append(", ".join(text) if text else "none")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def choosing_quiet() -> str:
    return choosing_table(0.0)


def choosing_noisy() -> str:
    return choosing_table(0.3)


def choosing_rule() -> str:
    """The comparison's ranking rule, quoted from the code (hilcontact.comparison.RANKING_RULE)."""
    from hilcontact.comparison import RANKING_RULE

    return RANKING_RULE


def write_images() -> list[Path]:
    """The images the pages show (only with --write): docs/img/choosing_stability_map.png,
    the noisy sweep's stability map with the faithful seeds per cell."""
    from hilcontact.plots import save_figures
    from hilcontact.stability import stability_map

    rows, _ = choosing_sweeps()
    noisy = rows[rows["facility.sensor_noise"] == CHOOSING_NOISE[-1]]
    figure = stability_map(noisy).figures()["stability_map"]
    save_figures({"choosing_stability_map": figure}, ROOT / "docs" / "img", dpi=90)
    return [ROOT / "docs" / "img" / "choosing_stability_map.png"]


# ---- docs/model.md: the paper's experiments with the facility's losses ------------------------


def paper_experiments_table() -> str:
    """Rebound speed per collision (mm/s) on `paper-exp-*-facility` and `paper-exp-*`, per
    compensator, and the fourth rebound against the initial 20 mm/s."""
    lines = ["| preset | compensator | rebound per collision (mm/s) | 4th / initial |", "|---|---|---|--:|"]
    for preset in ("paper-exp-1.93hz-facility", "paper-exp-2.64hz-facility", "paper-exp-1.93hz", "paper-exp-2.64hz"):
        for kind in ("none", "pic", "dac", "pida"):
            r = run(preset, kind)
            speeds = [c.get("rebound_speed") for c in r.metrics["collisions"]]
            text = ", ".join("-" if v is None else f"{v * 1e3:.1f}" for v in speeds)
            if r.status == "diverged":
                text += f" (diverged at {r.metrics['diverged_at']:.2f} s)"
            fourth = f"{speeds[3] / 0.02:.2f}" if len(speeds) > 3 and speeds[3] is not None else "-"
            lines.append(f"| `{preset}` | `{kind}` | {text} | {fourth} |")
    reference = run("paper-exp-2.64hz", "none").metrics["reference_collisions"]
    lines.append("| ideal reference, 2.64 Hz | | " + ", ".join(f"{c['rebound_speed'] * 1e3:.1f}" for c in reference) + " | |")
    return "\n".join(lines)


# ---- docs/benchmark.md: hil-bench-1 -------------------------------------------------------------


def benchmark_table() -> str:
    """docs/benchmark.md: the summary of hil-bench-1 for the shipped compensators (the whole
    suite, run into a temporary folder as `hilcontact benchmark` runs it)."""
    import tempfile

    from hilcontact import benchmark

    with tempfile.TemporaryDirectory() as folder:
        summary = benchmark.run_benchmark(Path(folder) / "b", plots=False)
    return benchmark.to_markdown(summary).rstrip("\n")


def benchmark_tolerances() -> str:
    """docs/benchmark.md: the tolerances of the verdict, the `[metrics]` defaults."""
    m = hc.load_scenario("paper-table1").metrics
    return (
        f"| `cov_tolerance` | {m.cov_tolerance:g} |\n| `max_cof` | {m.max_cof:g} |\n"
        f"| `max_velocity_error` | {m.max_velocity_error:g} |\n| `max_lost_collisions` | {m.max_lost_collisions} |\n"
        f"| `max_extra_collisions` | {m.max_extra_collisions} |\n| `judge_from` | {m.judge_from} |\n"
        f"| `contact_threshold` | {m.contact_threshold:g} N |"
    )


#: Every figure: name -> function writing its text.
FIGURES: dict[str, Callable[[], str]] = {
    "benchmark-table": benchmark_table,
    "benchmark-tolerances": benchmark_tolerances,
    "dac-table": dac_table,
    "pida-table": pida_table,
    "lead-table": lead_table,
    "zero-delay": zero_delay,
    "pic-table": pic_table,
    "tdpa-impedance-table": tdpa_impedance_table,
    "tdpa-admittance-table": tdpa_admittance_table,
    "energy-table": energy_table,
    "model-table": model_table,
    "damping-at-0.4": damping_at_04,
    "model-mediated-table": model_mediated_table,
    "readme-model-mediated": readme_model_mediated,
    "model-mediated-reach": model_mediated_reach,
    "choosing-quiet": choosing_quiet,
    "choosing-noisy": choosing_noisy,
    "choosing-rule": choosing_rule,
    "paper-experiments": paper_experiments_table,
}

#: Pages that hold figures.
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]

_REGION = re.compile(r"(<!-- doc-figures: ([a-z0-9.-]+) -->)(.*?)(<!-- /doc-figures -->)", re.S)


def regions(text: str) -> list[tuple[str, str]]:
    """The (name, current text) of each region of a page."""
    return [(m.group(2), m.group(3)) for m in _REGION.finditer(text)]


def _body(name: str, old: str, values: Mapping[str, str]) -> str:
    """A region's new text: a table on lines of its own, an inline figure inline."""
    value = values[name]
    return f"\n{value}\n" if old.startswith("\n") else value


def updated(text: str, values: Mapping[str, str]) -> str:
    """The page with every region's text replaced by its figure."""
    def replace(m: re.Match[str]) -> str:
        name = m.group(2)
        if name not in values:
            raise KeyError(f"unknown doc figure {name!r}; known: {', '.join(FIGURES)}")
        return m.group(1) + _body(name, m.group(3), values) + m.group(4)

    return _REGION.sub(replace, text)


def compute() -> dict[str, str]:
    return {name: make() for name, make in FIGURES.items()}


def stale_pages(values: Mapping[str, str]) -> dict[Path, tuple[str, str]]:
    """Pages whose regions differ from the figures: path -> (current, updated)."""
    out = {}
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        new = updated(text, values)
        if new != text:
            out[page] = (text, new)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--check", action="store_true", help="exit 1 if a page quotes other numbers")
    mode.add_argument("--write", action="store_true", help="update the pages")
    args = parser.parse_args(argv)
    values = compute()
    if not (args.check or args.write):
        for name, value in values.items():
            print(f"## {name}\n{value}\n")
        return 0
    stale = stale_pages(values)
    if args.write:
        for image in write_images():
            print(f"drew {image.relative_to(ROOT)}")
    for page, (old, new) in stale.items():
        name = page.relative_to(ROOT)
        if args.write:
            page.write_text(new, encoding="utf-8")
            print(f"updated {name}")
        else:
            sys.stdout.writelines(difflib.unified_diff(old.splitlines(True), new.splitlines(True), str(name), f"{name} (now)"))
    if args.check and stale:
        print(f"\n{len(stale)} page(s) quote stale figures: python scripts/doc_figures.py --write", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
