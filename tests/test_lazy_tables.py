"""`hc.simulate` hands its tables over as the core's records, made into DataFrames when first
read (issue 25, item 7): the frames are the ones made at once, read once, and a run that is
copied or compared reads them as before."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

import hilcontact as hc
from hilcontact import run as run_module
from hilcontact.native import core


def test_tables_are_made_when_first_read_and_equal_the_core_tables():
    scenario = hc.load_scenario("paper-table1", {"compensator.kind": "pida", "simulation.duration": 1.5})
    run = hc.simulate(scenario)
    assert isinstance(run.__dict__["_timeseries"], run_module._LazyFrame)
    assert isinstance(run.__dict__["_reference"], run_module._LazyFrame)
    timeseries = run.timeseries
    assert isinstance(run.__dict__["_timeseries"], pd.DataFrame) and run.timeseries is timeseries
    assert isinstance(run.__dict__["_reference"], run_module._LazyFrame)  # not read yet
    tables = core().simulate(scenario.to_json())["tables"]
    columns = tables.timeseries()
    assert list(timeseries.columns) == [c for c in run_module.TIMESERIES_COLUMNS + run_module.OPTIONAL_TIMESERIES_COLUMNS if c in columns]
    for name, values in columns.items():
        assert np.array_equal(timeseries[name].to_numpy(), values, equal_nan=True), name
    assert len(timeseries) == round(1.5 / 0.001) + 1
    reference = tables.reference()
    assert list(run.reference.columns) == run_module.REFERENCE_COLUMNS
    for name, values in reference.items():
        assert np.array_equal(run.reference[name].to_numpy(), values), name
    # a new dict of new arrays at each call
    again = tables.timeseries()
    assert again is not columns and again["time"] is not columns["time"]
    assert np.array_equal(again["time"], columns["time"])


def test_a_copied_run_and_an_assigned_table_behave_as_before():
    run = hc.simulate(hc.load_scenario("paper-table1", {"simulation.duration": 0.5}))
    copy = dataclasses.replace(run)
    assert copy.timeseries is run.timeseries and copy.reference is run.reference
    frame = pd.DataFrame({"time": [0.0, 1.0]})
    copy.timeseries = frame
    assert copy.timeseries is frame and run.timeseries is not frame
    assert "Run(scenario=" in repr(run)
