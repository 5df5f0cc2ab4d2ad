"""What a student sees, read from the lab page (browser tests): the readouts table, the
pole maps (uPlot's scales, series and points) and the pole map's colour legend."""

from __future__ import annotations

import time

from app.panels.readouts import WORD_JOINER
from lab_modules.formatting import INFINITY, MINUS_INFINITY, NOT_A_NUMBER, SUPERSCRIPT

#: the visible pole maps: title, x range, series labels and stroke colours, top-axis labels and
#: each series' points [[Re s, Im s], ...] (uPlot holds one x array; a series is NaN where it has no pole)
MAPS_JS = """() => Object.values((window.__viserTestpoints || {}).uplots || {}).map(v => v.chart)
    .filter(c => c.root.offsetParent !== null && /poles/i.test((c.root.querySelector('.u-title') || {}).innerText || ''))
    .map(c => ({title: c.root.querySelector('.u-title').innerText, x: [c.scales.x.min, c.scales.x.max],
                labels: c.series.slice(1).map(s => s.label), strokes: c.series.slice(1).map(s => s._stroke || s.stroke),
                top: (c.axes[2] || {})._values || null,
                points: c.data.slice(1).map(ys => Array.from(ys).map((y, i) => [c.data[0][i], y])
                                                     .filter(p => p[1] !== null && Number.isFinite(p[1])))}))"""
#: the visible readouts table (quantity | value | unit) as rows of cell texts
READOUTS_JS = """() => [...document.querySelectorAll('table')]
    .filter(t => t.offsetParent !== null && /quantity/.test((t.querySelector('thead') || t).innerText)).slice(0, 1)
    .flatMap(t => [...t.querySelectorAll('tbody tr')].map(r => [...r.querySelectorAll('td')].map(c => c.innerText.trim())))"""
#: the pole map's colour legend: {meaning: '#rrggbb'} from the coloured dots and the text after each
LEGEND_JS = """() => { const box = [...document.querySelectorAll('p, div')].filter(e => e.offsetParent !== null &&
        e.children.length && /^Colours \\(every exercise\\)/.test(e.innerText.trim())).pop();
    if (!box) return null;
    const hex = c => '#' + c.match(/\\d+/g).slice(0, 3).map(v => (+v).toString(16).padStart(2, '0')).join('');
    const out = {};
    box.querySelectorAll('span[style]').forEach(s => {
        let text = '', n = s.nextSibling;
        while (n && !(n.nodeType === 1 && n.matches('span[style]'))) { text += n.textContent; n = n.nextSibling; }
        out[text.replace(/\\u00a0/g, ' ').trim()] = hex(getComputedStyle(s).color); });
    return out; }"""
UNSUPERSCRIPT = str.maketrans({v: k for k, v in SUPERSCRIPT.items()})


def pole_maps(page, count: int = 2, timeout_s: float = 15.0) -> list[dict]:
    """The ``count`` visible pole maps (waits until they are drawn)."""
    deadline = time.time() + timeout_s
    maps = page.evaluate(MAPS_JS)
    while len(maps) < count and time.time() < deadline:
        time.sleep(0.25)
        maps = page.evaluate(MAPS_JS)
    assert len(maps) == count, maps
    return maps


def readout_rows(page) -> list[tuple[str, str, str]]:
    """The readouts table as read: (quantity, value, unit) texts, without the invisible word
    joiner that keeps a unit such as "N/µm" on one line."""
    return [tuple(cell.replace(WORD_JOINER, "") for cell in row)
            for row in page.evaluate(READOUTS_JS) if len(row) == 3]


def shown_number(text: str) -> float | str:
    """A readout value as the page shows it ("480 000", "7.5·10⁻⁸", "—", "∞") as a float;
    anything else (a word, or a formula) comes back as the text."""
    plain = text.replace("\u202f", "")
    if plain == NOT_A_NUMBER:
        return float("nan")
    if plain in (INFINITY, MINUS_INFINITY):
        return float(plain.replace(INFINITY, "inf"))
    if "·10" in plain:
        mantissa, exponent = plain.split("·10", 1)
        plain = f"{mantissa}e{exponent.translate(UNSUPERSCRIPT)}"
    try:
        return float(plain)
    except ValueError:
        return text
