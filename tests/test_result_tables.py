"""The report's tables are declared once (popnavshift/result_tables.py): every declared table
belongs to a section of the page, every section shows only its own tables, a table written
but not declared is an error, and a reported study's tables match their declaration."""

from __future__ import annotations

import pandas as pd
import pytest

import popnavshift
from popnavshift.errors import UnknownNameError
from popnavshift.report.build import write_tables
from popnavshift.report.page import SECTIONS
from popnavshift.result_tables import RESULT_TABLES, RESULTS, check_declared, csv_path


def test_every_declared_table_belongs_to_a_section_of_the_page():
    ids = [s.id for s in SECTIONS]
    assert len(RESULTS) == len(RESULT_TABLES)  # one declaration per name
    assert [t.name for t in RESULT_TABLES if t.section not in ids] == []
    order = [ids.index(t.section) for t in RESULT_TABLES]
    assert order == sorted(order)  # declared in the order of the page
    assert all(t.doc.startswith("one ") and t.key for t in RESULT_TABLES)


def test_a_section_needs_only_tables_declared_with_it():
    wrong = [(s.id, n) for s in SECTIONS for n in s.needs if RESULTS[n].section != s.id]
    assert wrong == []


def test_a_table_or_a_reason_not_declared_is_refused(tmp_path):
    with pytest.raises(ValueError, match="report tables not declared.*: bogus"):
        write_tables({"reversals": pd.DataFrame({"a": [1]}), "bogus": pd.DataFrame()}, tmp_path)
    assert not (tmp_path / "tables").exists()  # refused before anything is written
    with pytest.raises(UnknownNameError, match="unknown report table 'reversal'.*'reversals'"):
        csv_path("reversal")
    check_declared(["evidence_headline", "robust_seeds"], "missing")


def test_a_reported_study_writes_declared_tables_identified_by_their_key(reported_study):
    written = sorted(p.stem for p in (reported_study / "report" / "tables").glob("*.csv"))
    assert [n for n in written if n not in RESULTS] == []
    tables = popnavshift.results(reported_study)
    assert list(tables) == [t.name for t in RESULT_TABLES if t.name in written]
    for name, df in tables.items():
        key = list(RESULTS[name].key)
        assert set(key) <= set(df.columns), name
        assert not df.duplicated(key).any(), name


def test_the_page_links_each_table_from_its_own_section(reported_study):
    html = (reported_study / "report" / "index.html").read_text("utf-8")
    for part in html.split('<section id="')[1:]:
        section = part.split('"', 1)[0]
        linked = {t.name for t in RESULT_TABLES if f'href="{csv_path(t.name)}"' in part
                  and "</section>" not in part.split(csv_path(t.name))[0]}
        assert {RESULTS[n].section for n in linked} <= {section}, section
