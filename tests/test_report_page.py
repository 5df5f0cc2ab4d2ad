"""Issue 25, the ``reproduce --html`` report: figures for every exercise, a page that fits a 1366 px
screen and prints on A4 (the claims table and the link row laid out to the page's width)."""

from __future__ import annotations

import pytest
from matplotlib.figure import Figure

from app.commands.reproduce import write_html
from lab_modules.evaluation.measured_claims import Row
from lab_modules.exercises import get, registry
from tests.conftest import browser_only

A4_WIDTH_PX = 794                 # 210 mm at 96 px per inch: what a printed page lays out to


@pytest.mark.parametrize("name", list(registry()))
def test_every_exercise_has_report_figures(name):
    exercise = get(name)
    figures = exercise.report_figures(exercise.resolve({}))
    assert figures and all(isinstance(figure, Figure) for figure in figures)


class FigureStub:
    """An exercise as the report reads it, with one small figure (the layout, not the physics)."""

    def __init__(self, name: str, title: str):
        self.name, self.title = name, title

    def resolve(self, overrides: dict) -> dict:
        return {}

    def report_figures(self, values: dict) -> list:
        figure = Figure(figsize=(6, 3))
        figure.add_subplot().plot([0, 1], [0, 1])
        return [figure]


def _page_widths(page, url: str, width: int, media: str) -> dict:
    page.set_viewport_size({"width": width, "height": 768})
    page.emulate_media(media=media)
    page.goto(url)
    return page.evaluate("""() => ({page: document.documentElement.scrollWidth,
        nav: getComputedStyle(document.querySelector('nav')).display,
        tables: Math.max(...[...document.querySelectorAll('table')].map(t => t.getBoundingClientRect().right))})""")


@browser_only[0]
@browser_only[1]
def test_the_report_fits_a_laptop_screen_and_an_a4_page(browser, tmp_path):
    """Every claim of every exercise in the table and every exercise in the link row: no sideways
    scrolling at 1366 px; printed, the link row is left out and the table fits A4's width."""
    exercises = [FigureStub(name, get(name).title) for name in registry()]
    rows = [Row(name, claim, [1.0]) for name in registry() for claim in get(name).claims]
    path = write_html(tmp_path, rows, exercises, "seed 0")
    page = browser.new_page()
    try:
        screen = _page_widths(page, path.as_uri(), 1366, "screen")
        assert screen["page"] <= 1366 and screen["tables"] <= 1366 and screen["nav"] == "flex", screen
        printed = _page_widths(page, path.as_uri(), A4_WIDTH_PX, "print")
        assert printed["page"] <= A4_WIDTH_PX and printed["nav"] == "none", printed
    finally:
        page.close()
