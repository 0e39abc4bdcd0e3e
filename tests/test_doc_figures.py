"""The numbers the docs quote agree with fresh runs (scripts/doc_figures.py)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "doc_figures.py"


@pytest.fixture(scope="module")
def doc_figures(core):
    spec = importlib.util.spec_from_file_location("doc_figures", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["doc_figures"] = module
    spec.loader.exec_module(module)
    return module


def test_the_docs_quote_what_the_runs_give(doc_figures):
    values = doc_figures.compute()
    stale = doc_figures.stale_pages(values)
    assert not stale, f"stale figures in {sorted(str(p) for p in stale)}: run python scripts/doc_figures.py --write"


def test_every_figure_is_quoted_and_every_region_is_known(doc_figures):
    used = {name for page in doc_figures.PAGES for name, _ in doc_figures.regions(page.read_text(encoding="utf-8"))}
    assert used == set(doc_figures.FIGURES)


def test_a_changed_number_is_caught(doc_figures):
    values = doc_figures.compute()
    page = "intro <!-- doc-figures: zero-delay -->CoV 1.5<!-- /doc-figures --> end"
    assert doc_figures.updated(page, values) == f"intro <!-- doc-figures: zero-delay -->{values['zero-delay']}<!-- /doc-figures --> end"
    with pytest.raises(KeyError, match="unknown doc figure 'nope'"):
        doc_figures.updated("<!-- doc-figures: nope -->x<!-- /doc-figures -->", values)
