"""Typeset formulas in the lab's Markdown: ``$…$`` (inline) and ``$$…$$`` (display) LaTeX
becomes MathML, which every current browser renders natively.

viser 1.1.1's Markdown (react-markdown with remark-gfm) has no math plugin, but it renders raw
HTML, MathML included.  So the worksheets are written in LaTeX, readable as source (and as
rendered Markdown elsewhere), and converted on the server by ``latex2mathml``.  The MathML is
one line of tags whose text is entity-escaped, so Markdown finds nothing in it to italicise.
Code spans (`` `…` ``) are left as they are.
"""

from __future__ import annotations

import functools
import re

from latex2mathml.converter import convert

#: a code span or fenced block (left alone), display math, inline math.  Inline math follows
#: pandoc's rule: no space after the opening or before the closing ``$``, no digit after the
#: closing one (so "$5 and $6" stays text).
_TOKENS = re.compile(r"(?P<code>```.*?```|`[^`\n]*`)"
                     r"|\$\$(?P<display>.+?)\$\$"
                     r"|(?<![\\$\w])\$(?P<inline>[^\s$](?:[^$\n]*?[^\s$\\])?)\$(?![\w$])", re.DOTALL)
#: characters that mean something to Markdown (or a GFM table) inside the MathML's text
_MARKDOWN_SPECIAL = re.compile(r"[\\`*_{}\[\]|~$]")


def _escape_text(mathml: str) -> str:
    """Every character Markdown could read as syntax, in the text between tags, as an entity."""
    def text(match: re.Match) -> str:
        return _MARKDOWN_SPECIAL.sub(lambda c: f"&#{ord(c.group())};", match.group())
    return re.sub(r"(?<=>)[^<]+(?=<)", text, mathml)


@functools.lru_cache(maxsize=4096)
def mathml(latex: str, display: bool = False) -> str:
    """One formula as MathML on one line (``display``: a centred block)."""
    # latex2mathml sets a one-letter \mathrm{A} in italics (a multi-letter one upright): as text
    latex = re.sub(r"\\mathrm\{(\w)\}", r"\\text{\1}", latex.strip())
    markup = convert(latex, display="block" if display else "inline")
    markup = markup.replace(' xmlns="http://www.w3.org/1998/Math/MathML"', "").replace("\n", " ")
    return _escape_text(markup)


def formulas(markdown: str) -> list[tuple[str, bool]]:
    """The formulas of ``markdown``: (LaTeX, display?) in order."""
    found = []
    for match in _TOKENS.finditer(markdown):
        if match.group("display") is not None:
            found.append((match.group("display"), True))
        elif match.group("inline") is not None:
            found.append((match.group("inline"), False))
    return found


def typeset(markdown: str) -> str:
    """``markdown`` with its ``$…$`` and ``$$…$$`` formulas as MathML."""
    def replace(match: re.Match) -> str:
        if match.group("code") is not None:
            return match.group("code")
        if match.group("display") is not None:
            return mathml(match.group("display"), display=True)
        return mathml(match.group("inline"))
    return _TOKENS.sub(replace, markdown)
