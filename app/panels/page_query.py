"""The page's query string (``?assignment=CODE``, ``?instructor``, ``?experiment=CODE``), read in the
browser: viser opens its websocket at the page's address without the query, so the server never
sees it.  A hidden text box receives it from a script of the page, and its update reaches the
server like any control's value.

The script runs from an image's ``onerror`` (an HTML element's ``<script>`` is not run when React
inserts it); it does nothing on a page without a query, so an ordinary tab sends nothing.  What it
reports is what the student could type anyway: the tab treats it as typed input."""

from __future__ import annotations

from collections.abc import Callable
from urllib.parse import parse_qs

from app.infra.viser_internals import element_id

LABEL = "Page query"
QUERY_CHARACTERS = 300            # longer queries are cut: a code or a word is all the lab reads

#: The element ids viser gives are UUIDs; the label viser renders for the box carries its id.
_SCRIPT = (
    "(function report(tries) {{"
    " if (!location.search) return;"
    " var label = Array.prototype.find.call(document.getElementsByTagName('label'),"
    " function (l) {{ return l.htmlFor === '{id}'; }});"
    " if (!label) {{ if (tries < 100) setTimeout(function () {{ report(tries + 1); }}, 100); return; }}"
    " var input = label.closest('.mantine-Flex-root').querySelector('input');"
    " Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, 'value').set"
    ".call(input, location.search.slice(0, {limit}));"
    " input.dispatchEvent(new Event('input', {{bubbles: true}}));"
    "}})(0)")


def parsed(query: str) -> dict[str, str]:
    """``?a=1&b`` -> {"a": "1", "b": ""}: the first value of each name, spaces at the ends dropped."""
    fields = parse_qs(str(query or "").lstrip("?")[:QUERY_CHARACTERS], keep_blank_values=True)
    return {name: values[0].strip() for name, values in fields.items()}


def add(gui, on_query: Callable[[dict[str, str]], None], on) -> None:
    """The hidden box and the script that fills it; ``on_query(fields)`` once the page reported its
    query (through the tab's worker: ``on(key, action)``)."""
    box = gui.add_text(LABEL, "")
    identity = element_id(box)
    box.on_update(on("page query", lambda: on_query(parsed(box.value))))
    script = _SCRIPT.format(id=identity, limit=QUERY_CHARACTERS).replace('"', "&quot;")
    gui.add_html(f'<style>div:has(> .mantine-Flex-root label[for="{identity}"]) {{ display: none; }}</style>'
                 f'<img alt="" src="data:," style="display: none" onerror="{script}">')
