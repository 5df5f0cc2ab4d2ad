"""Worksheets as a student's browser parses them (issue 11, defect 12): formulas typeset
as MathML, no identifier italicised by its underscores, no LaTeX left as text.

The worksheets are parsed by markdown-it (CommonMark with GFM tables, like viser's
react-markdown with remark-gfm) after ``app.panels.worksheets.text`` has typeset them."""

from __future__ import annotations

import re

import pytest
from markdown_it import MarkdownIt

from app.panels import worksheets
from app.panels.typeset import formulas, mathml, typeset
from tests.example_exercise import contract_exercises

EXERCISES = list(contract_exercises().values())
MARKDOWN = MarkdownIt("commonmark").enable("table")


def _inline_tokens(markdown: str):
    for token in MARKDOWN.parse(markdown):
        if token.type == "inline":
            yield from token.children


def _text_outside_code_and_math(markdown: str) -> list[str]:
    return [t.content for t in _inline_tokens(markdown) if t.type == "text"]


@pytest.mark.parametrize("exercise", EXERCISES, ids=[e.name for e in EXERCISES])
def test_worksheet_has_no_stray_italics_and_no_raw_latex(exercise):
    sheet = worksheets.text(exercise, [1.0] * len(exercise.claims))
    tokens = list(_inline_tokens(sheet))
    underscored = [t for t in tokens if t.type in ("em_open", "strong_open") and "_" in t.markup]
    assert not underscored, f"{exercise.name}: emphasis from underscores"
    source = (worksheets.STATIC / "worksheets" / exercise.worksheet).read_text(encoding="utf-8")
    texts = _text_outside_code_and_math(typeset(source))  # the claims table escapes its own identifiers
    identifiers = [m.group() for text in texts for m in re.finditer(r"\S*[^\s_]_[^\s_]\S*", text)]
    assert not identifiers, f"{exercise.name}: identifiers as plain text (write $k_x$ or `name`): {identifiers}"
    leftovers = [text for text in _text_outside_code_and_math(sheet) if "$" in text or re.search(r"\\[a-zA-Z]+", text)]
    assert not leftovers, f"{exercise.name}: LaTeX outside math: {leftovers}"
    html = "".join(t.content for t in tokens if t.type == "html_inline")
    assert html.count("<math") == html.count("</math>") > 0, f"{exercise.name}: no formula typeset"
    assert "<merror" not in html, exercise.name


@pytest.mark.parametrize("exercise", EXERCISES, ids=[e.name for e in EXERCISES])
def test_every_formula_of_the_worksheet_converts(exercise):
    source = (worksheets.STATIC / "worksheets" / exercise.worksheet).read_text(encoding="utf-8")
    for latex, display in formulas(source):
        markup = mathml(latex, display)
        assert markup.startswith("<math") and markup.endswith("</math>"), latex
        assert not re.search(r">[^<]*\\[a-zA-Z]", markup), f"{exercise.name}: unknown command left in {latex!r}"
        assert ">&<" not in markup, f"{exercise.name}: an '&' shown as text (environment not supported) in {latex!r}"


def test_typeset_leaves_code_prices_and_escaped_dollars_alone():
    text = r"costs $5 and $6, `a_$b$` and \$x\$ but $k_x$ and $$\sigma_x$$"
    out = typeset(text)
    assert "costs $5 and $6, `a_$b$` and \\$x\\$ but <math" in out
    assert out.count("<math") == 2 and 'display="block"' in out
    italics = [t for t in _inline_tokens(typeset("$K_{mx} x_d$ and $i_{\\mathrm{ref}}$ *a*"))
               if t.type == "em_open"]
    assert len(italics) == 1                          # only the deliberate *a*
