"""Comparison figures read like the paper's: no text overlaps at any number of compensators,
identification axes show the convergence, not the initial guess."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import synthetic_run

import hilcontact as hc
from hilcontact.comparison import ALL_KINDS, Comparison
from hilcontact.plots import comparison_figures, converged_range, identification_figure


def fake(kinds) -> dict[str, hc.Run]:
    runs = {}
    for kind in kinds:
        run = synthetic_run(estimates=True)
        run.metrics = json.loads(json.dumps(run.metrics))
        run.scenario = hc.load_scenario("paper-table1", {"compensator.kind": kind})
        run.metrics["status"] = "unfaithful"  # the longest panel titles
        runs[kind] = run
    return runs


def texts(figure):
    """Every title's and tick label's box, in pixels."""
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    boxes = []
    if figure._suptitle is not None:
        boxes.append(("suptitle", figure._suptitle.get_window_extent(renderer)))
    for i, ax in enumerate(a for a in figure.axes if a.get_visible()):
        if ax.get_title():
            boxes.append((f"title {i}: {ax.get_title()}", ax.title.get_window_extent(renderer)))
        for label in ax.get_xticklabels():
            if label.get_visible() and label.get_text():
                boxes.append((f"xtick {i}", label.get_window_extent(renderer)))
        if ax.xaxis.label.get_text():
            boxes.append((f"xlabel {i}", ax.xaxis.label.get_window_extent(renderer)))
    return boxes


@pytest.mark.parametrize("count", range(1, len(ALL_KINDS) + 1))
def test_no_title_overlaps_anything(count):
    figures = comparison_figures(fake(list(ALL_KINDS)[:count]))
    for name, figure in figures.items():
        boxes = texts(figure)
        titles = [(label, box) for label, box in boxes if label.startswith(("suptitle", "title"))]
        for label, box in titles:
            for other, other_box in boxes:
                if other != label:
                    assert not box.overlaps(other_box), f"{name}, {count} compensators: {label!r} overlaps {other!r}"
            width, height = figure.canvas.get_width_height()
            assert 0 <= box.x0 and box.x1 <= width and 0 <= box.y0 and box.y1 <= height, f"{name}: {label} outside"


def test_identification_axes_show_the_convergence_not_the_initial_guess():
    run = synthetic_run(estimates=True)
    time = run.timeseries["time"].to_numpy()
    end = run.metrics["collisions"][0]["end"]
    rng = np.random.default_rng(1)
    # the initial guess, 300 N/mm, until the first collision ends; then 170 ± 0.5 N/mm
    run.timeseries["stiffness_estimate"] = np.where(time <= end, 300e3, 170e3 + 500.0 * rng.standard_normal(time.size))
    lo, hi = converged_range(run, "stiffness_estimate", run.scenario.contact.stiffness)
    assert lo < 168e3 and hi < 200e3 and lo <= 176275.0 <= hi  # the true value shows, the guess does not
    ax_k = identification_figure(run).axes[0]
    bottom, top = ax_k.get_ylim()
    assert top < 300.0 and bottom <= 170.0 <= top
    figure = comparison_figures({"pida": run})["compare_identification"]
    assert figure.axes[0].get_ylim()[1] < 300.0


def test_the_rule_of_the_tolerance_lines():
    runs = fake(["pida", "dac"])
    cov_ax, cof_ax = comparison_figures(runs)["compare_cov_cof"].axes[:2]
    levels = lambda ax: sorted({round(float(line.get_ydata()[0]), 6) for line in ax.get_lines()})  # noqa: E731
    assert levels(cov_ax) == [0.95, 1.0, 1.05]
    assert levels(cof_ax) == [1.0, 1.2]
