"""The numbers README.md and docs/*.md quote, rerun (``python -m scripts.check_doc_numbers``).

Every registered quote must still be in its doc, and every number must be what the code
measures today, within half a unit of its last quoted digit. The cheap sources run in the
quick suite; the slow ones (a 200-landmark grid, the rendered accuracy table) are marked
slow, so CI runs them; the long ones (seed sweeps) and those that need the shared data are
left to the script (``--long``, ``--shared``).
"""

from __future__ import annotations

import pytest

from scripts import check_doc_numbers
from scripts.doc_numbers.quotes import ROOT, Checker, Context, Quote, Source, numbers_in, parse_number, quote_in_doc
from scripts.doc_numbers.readers import markdown_rows
from scripts.doc_numbers.registry import QUOTES
from scripts.doc_numbers.sources import SOURCES

BY_NAME = {s.name: s for s in SOURCES}


def test_every_quote_is_where_the_registry_says():
    problems = [problem for q in QUOTES if (problem := quote_in_doc(q))]
    assert not problems, "\n".join(problems)


def test_every_quote_has_a_source_and_sources_are_unique():
    assert len(BY_NAME) == len(SOURCES)
    assert {q.source for q in QUOTES} <= set(BY_NAME)
    assert {s.name for s in SOURCES if not s.shared} <= {q.source for q in QUOTES}, "a source no quote reads"


def test_numbers_are_whole_numbers_of_the_text():
    assert numbers_in("ekf-s001 0.0110 m, −4.8 … +3.1 %, 6 621 poses, isam2 9/9, 8   447.8 ms, ends 6 969.") == \
        ["0.0110", "−4.8", "3.1", "6 621", "9", "9", "8", "447.8", "6 969"]
    assert parse_number("6 621") == 6621 and parse_number("−4.8") == -4.8


def test_a_scripts_markdown_table_is_read_row_by_row_without_its_header():
    table = "| distance | seed 000 | seed 002 |\n|---:|---:|---:|\n| 0.5 m | 1.58° | — |\n| 1.0 m | 2.77° | 12.3 % |"
    assert markdown_rows(table) == {"0.5 m": ["0.5", "1.58"], "1.0 m": ["1.0", "2.77", "12.3"]}


def _toy(tmp_path, measured, *, shared=None, text="ATE 0.0110 m"):
    (tmp_path / "doc.md").write_text(f"The run: {text}.\n", encoding="utf-8")
    source = Source("toy", "toy", "cheap", lambda context: measured, shared=shared)
    quote = Quote("doc.md", text, "0.0110", "toy", lambda result: result, "toy ATE")
    checker = Checker({"toy": source}, Context(tmp_path, None, tmp_path))
    return checker.check(quote)


def test_a_number_off_by_more_than_its_last_digit_is_a_mismatch(tmp_path):
    assert _toy(tmp_path, 0.01104).status == "ok"
    assert _toy(tmp_path, 0.01096).status == "ok"
    outcome = _toy(tmp_path, 0.01106)
    assert outcome.status == "MISMATCH" and outcome.failed and outcome.measured == 0.01106


def test_a_quote_no_longer_in_the_doc_fails_without_measuring(tmp_path):
    calls = []
    (tmp_path / "doc.md").write_text("ATE 0.0111 m\n", encoding="utf-8")
    source = Source("toy", "toy", "cheap", lambda context: calls.append(1))
    quote = Quote("doc.md", "ATE 0.0110 m", "0.0110", "toy", float, "toy ATE")
    outcome = Checker({"toy": source}, Context(tmp_path, None, tmp_path)).check(quote)
    assert outcome.status == "NOT IN DOC" and outcome.failed and not calls


def test_a_source_needing_the_shared_data_is_skipped_with_the_reason(tmp_path):
    outcome = _toy(tmp_path, 0.0110, shared="data/mrclam")
    assert outcome.status == "skipped" and not outcome.failed
    assert "--shared" in outcome.reason


def test_a_failing_source_is_an_error_not_a_crash(tmp_path):
    (tmp_path / "doc.md").write_text("ATE 0.0110 m\n", encoding="utf-8")
    source = Source("toy", "toy", "cheap", lambda context: 1 / 0)
    quote = Quote("doc.md", "ATE 0.0110 m", "0.0110", "toy", float, "toy ATE")
    outcome = Checker({"toy": source}, Context(tmp_path, None, tmp_path)).check(quote)
    assert outcome.status == "ERROR" and "ZeroDivisionError" in outcome.reason


def test_the_command_exits_nonzero_on_a_mismatch(tmp_path, monkeypatch, capsys):
    (tmp_path / "doc.md").write_text("ATE 0.0110 m\n", encoding="utf-8")
    monkeypatch.setattr(check_doc_numbers, "ROOT", tmp_path)
    monkeypatch.setattr(check_doc_numbers, "SOURCES", [Source("toy", "toy", "cheap", lambda context: 0.02)])
    monkeypatch.setattr(check_doc_numbers, "QUOTES", [Quote("doc.md", "ATE 0.0110 m", "0.0110", "toy", float, "t")])
    assert check_doc_numbers.main([]) == 1
    assert "MISMATCH" in capsys.readouterr().out
    monkeypatch.setattr(check_doc_numbers, "SOURCES", [Source("toy", "toy", "cheap", lambda context: 0.011)])
    assert check_doc_numbers.main([]) == 0


@pytest.fixture(scope="module")
def checker(tmp_path_factory):
    return Checker(BY_NAME, Context(ROOT, None, tmp_path_factory.mktemp("doc_numbers")), ("cheap", "slow"))


def _params(cost):
    marks = [pytest.mark.slow] if cost == "slow" else []
    return [pytest.param(s.name, marks=marks, id=s.name) for s in SOURCES if s.cost == cost and not s.shared]


@pytest.mark.parametrize("source", _params("cheap") + _params("slow"))
def test_the_docs_numbers_match_a_rerun(checker, source):
    outcomes = [checker.check(q) for q in QUOTES if q.source == source]
    bad = [o for o in outcomes if o.status != "ok"]
    assert outcomes and not bad, "\n".join(
        f"{o.status} {o.quote.doc}: quoted {o.quote.number}, measured {o.measured} ({o.quote.label}) {o.reason}"
        for o in bad)
