"""``python -m app reproduce``: every exercise's paper claims, measured now.

Each exercise declares the headline results of its paper as ``Claim``s
(``lab_modules/claims.py``).  This command runs the headless metrics behind
them (each distinct run once), prints the table paper vs lab with the range
the lab holds itself to, and exits with status 1 when a claim fails.

Quick and full:
* ``--quick``: each claim once, at its own settings, run length and seed 0
  (exactly what ``tests/test_claims.py`` checks; well under 3 minutes on 2 cores).
* default: the same claims on seeds 0 to 4 (exercises without a random
  seed, e.g. a recording's replay, run once); a claim passes only if it holds
  on every seed, and the table shows seed 0's value with the range over seeds.

``--html DIR`` also writes ``DIR/index.html``: the table plus, per exercise,
the figures that back its claims (``Exercise.report_figures``, matplotlib,
embedded as PNG), one self-contained page.
"""

from __future__ import annotations

import base64
import html
import io
import json
import sys
import time
import traceback
from pathlib import Path

from app.commands.headless import jsonable
from lab_modules.claims import format_value
from lab_modules.evaluation.measured_claims import (
    DEVIATION,
    FAIL,
    FULL_SEEDS,
    MEASUREMENT_ERRORS,
    PASS,
    QUICK_SEEDS,
    Row,
    measure,
)
from lab_modules.exercises import Exercise, get, registry
from lab_modules.formatting import NOT_A_NUMBER
from lab_modules.parameters import ParameterError

FIGURE_DPI = 100


COLUMNS = ("exercise", "source", "quantity", "paper", "lab", "accepted", "status")


def lab_text(row: Row) -> str:
    """Seed 0's value with its unit and, where the seeds differ, their range: each value with the
    digits that place it inside or outside the accepted range as the verdict does; "—" where the
    metric could not be measured (the reason says why)."""
    if row.value is None:
        return NOT_A_NUMBER
    text = row.claim.value_text(row.value)
    if len(row.values) > 1 and min(row.values) != max(row.values):
        low, high = (format_value(value, row.claim.accept) for value in (min(row.values), max(row.values)))
        text += f" ({low} … {high})"
    return text


def _cells(row: Row) -> tuple[str, ...]:
    return (row.exercise, row.claim.source, row.quantity_text(), row.claim.paper, lab_text(row),
            row.claim.accept_text(), row.status)


def text_table(rows: list[Row]) -> str:
    """The table for a terminal: one line per claim, the reason for a deviation or failure below it."""
    cells = [_cells(row) for row in rows]
    widths = [max(len(column), *(len(c[i]) for c in cells)) for i, column in enumerate(COLUMNS)]
    lines = ["  ".join(column.ljust(w) for column, w in zip(COLUMNS, widths)).rstrip(),
             "  ".join("-" * w for w in widths)]
    for row, cell in zip(rows, cells):
        lines.append("  ".join(text.ljust(w) for text, w in zip(cell, widths)).rstrip())
        if row.reason:
            lines.append(f"    {'reason' if row.status != FAIL else 'FAIL'}: {row.reason}")
    return "\n".join(lines)


def summary(rows: list[Row], quick: bool, seconds: float) -> str:
    counts = {s: sum(r.status == s for r in rows) for s in (PASS, DEVIATION, FAIL)}
    mode = "quick: seed 0" if quick else f"seeds {', '.join(map(str, FULL_SEEDS))}"
    return (f"{len(rows)} claims ({mode}): {counts[PASS]} pass, {counts[DEVIATION]} documented deviations "
            f"(hold), {counts[FAIL]} fail; {seconds:.0f} s")


# -- HTML report -------------------------------------------------------------------------------
#: The page fits a 1366 px screen (no sideways scrolling: the links wrap, long names break, the table
#: is laid out to the page's width) and prints on A4/Letter (no sticky header, figures not split).
STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.2em 1.5em; color: #222; max-width: 1300px; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { font-size: 1.2em; margin-top: 1.6em; }
p.meta { color: #555; margin-top: 0; }
table { border-collapse: collapse; font-size: 13px; width: 100%; table-layout: fixed; }
th, td { border: 1px solid #ccc; padding: 3px 6px; text-align: left; vertical-align: top;
         overflow-wrap: break-word; }
th { background: #f0f0f0; position: sticky; top: 0; }
col.exercise { width: 8%; } col.source { width: 10%; } col.quantity { width: 20%; } col.paper { width: 10%; }
col.lab { width: 8%; } col.accepted { width: 8%; } col.status { width: 8%; } col.reason { width: 28%; }
tr.pass td.status { color: #17692d; font-weight: 600; }
tr.deviation td.status { color: #8a5a00; font-weight: 600; }
tr.fail td.status { color: #b00020; font-weight: 700; } tr.fail { background: #fff0f0; }
td.reason { color: #555; font-size: 12px; }
.figures { display: grid; grid-template-columns: repeat(auto-fill, minmax(min(560px, 100%), 1fr)); gap: 8px; }
figure { margin: 0.6em 0; } figure img { width: 100%; height: auto; border: 1px solid #eee; }
figcaption { color: #555; font-size: 12px; }
nav { display: flex; flex-wrap: wrap; gap: 0.3em 1em; }
@media print {
  body { margin: 0; max-width: none; font-size: 11px; }
  nav { display: none; }
  th { position: static; }
  table { font-size: 9px; } td.reason { font-size: 8px; }
  tr, figure { break-inside: avoid; }
  section { break-before: page; }
  .figures { display: block; }
  figure img { max-width: 100%; border: none; }
}
"""


def _png(figure) -> str:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=FIGURE_DPI)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _table_html(rows: list[Row]) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in (*COLUMNS, "note / reason"))
    body = []
    for row in rows:
        css = {PASS: "pass", DEVIATION: "deviation", FAIL: "fail"}[row.status]
        cells = _cells(row)
        note = row.reason or row.claim.note
        tds = "".join(f'<td class="{"num" if i in (4, 5) else ""}">{html.escape(text)}</td>'
                      for i, text in enumerate(cells[:-1]))
        body.append(f'<tr class="{css}">{tds}<td class="status">{html.escape(cells[-1])}</td>'
                    f'<td class="reason">{html.escape(note)}</td></tr>')
    widths = "".join(f'<col class="{name}">' for name in (*COLUMNS, "reason"))
    return f"<table><colgroup>{widths}</colgroup><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def write_html(directory: Path, rows: list[Row], exercises: list[Exercise], headline: str, log=None) -> Path:
    """``directory/index.html``: the table and each exercise's figures (PNG embedded as base64)."""
    import matplotlib
    matplotlib.use("Agg")
    sections = []
    for exercise in exercises:
        started = time.perf_counter()
        try:
            figures = exercise.report_figures(exercise.resolve({}))
            images = "".join(f'<figure><img alt="{html.escape(exercise.name)} figure {i + 1}" '
                             f'src="data:image/png;base64,{_png(f)}"></figure>' for i, f in enumerate(figures))
        except MEASUREMENT_ERRORS:
            images = f"<pre>{html.escape(traceback.format_exc())}</pre>"
            figures = []
        if log:
            log(f"{exercise.name}: {len(figures)} figures, {time.perf_counter() - started:.1f} s")
        own = [r for r in rows if r.exercise == exercise.name]
        shown = f'<div class="figures">{images}</div>' if images else "<p>No figures.</p>"
        sections.append(f'<section id="{exercise.name}"><h2>{html.escape(exercise.name)}: '
                        f'{html.escape(exercise.title)}</h2>{_table_html(own)}{shown}</section>')
    nav = "".join(f'<a href="#{e.name}">{html.escape(e.name)}</a>' for e in exercises)
    page = (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>AMB estimation lab: paper claims reproduced</title><style>{STYLE}</style></head><body>"
            f"<h1>AMB estimation lab: paper claims reproduced</h1><p class=\"meta\">{html.escape(headline)}. "
            f"Generated by <code>python -m app reproduce</code>; the claims live in each exercise's file "
            f"(<code>claims = (Claim(…), …)</code>).</p><nav>{nav}</nav>"
            f"<h2>All claims</h2>{_table_html(rows)}{''.join(sections)}</body></html>")
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / "index.html"
    path.write_text(page, encoding="utf-8")
    return path


def main(as_json: bool, quick: bool, html_dir: str | None, only: list[str]) -> int:
    """Measure, print, optionally write the report; 1 when a claim fails."""
    exercises = [get(name) for name in only] if only else list(registry().values())
    directory = Path(html_dir) if html_dir else None
    if directory is not None and directory.exists() and not directory.is_dir():
        raise ParameterError(f"--html {html_dir!r} is a file: expected a directory (created if missing)")

    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    started = time.perf_counter()
    rows = measure(exercises, quick, log)
    headline = summary(rows, quick, time.perf_counter() - started)
    if as_json:
        print(json.dumps(jsonable({"quick": quick, "seeds": list(QUICK_SEEDS if quick else FULL_SEEDS),
                                    "summary": headline, "claims": [r.as_dict() for r in rows]}),
                         indent=2, ensure_ascii=False))
    else:
        print(text_table(rows))
        print(headline)
    if directory is not None:
        path = write_html(directory, rows, exercises, headline, log)
        log(f"report: {path}")
    return 1 if any(r.status == FAIL for r in rows) else 0
