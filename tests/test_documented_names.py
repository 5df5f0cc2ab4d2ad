"""Documentation that stays true: every dotted name of the project's packages (``lab_modules.…``,
``app.…``) mentioned in a docstring or a comment of ``lab_modules/``, ``app/`` and ``tests/``, or
anywhere in README.md and DEVELOPERS.md, with or without backticks, names something that exists.

A name exists when its longest importable prefix is a module and the rest are attributes, one
inside the other (``lab_modules.claims.Claim.holds``).  Attributes that only instances get (set in
``__init__``) are not found: name the class or the module instead.  Paths (``app/tab/session.py``) and
names relative to a package (``exercises.MODULES``) are not checked here; paths are, below."""

from __future__ import annotations

import ast
import importlib
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: A dotted name from one of the project's packages, not the tail of a longer word, name or path
DOTTED = re.compile(r"(?<![\w./-])(?:lab_modules|app)(?:\.[A-Za-z_]\w*)+")
FILES = sorted([*ROOT.joinpath("lab_modules").rglob("*.py"), *ROOT.joinpath("app").rglob("*.py"),
                *ROOT.joinpath("tests").rglob("*.py")]) + [ROOT / "README.md", ROOT / "DEVELOPERS.md"]


def documentation(path: Path) -> list[str]:
    """What documents the code in ``path``: a Markdown file whole; of Python source its docstrings
    (every string that stands alone as a statement) and its comments."""
    text = path.read_text(encoding="utf-8")
    if path.suffix == ".md":
        return [text]
    docstrings = [node.value.value for node in ast.walk(ast.parse(text))
                  if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
                  and isinstance(node.value.value, str)]
    comments = [token.string for token in tokenize.generate_tokens(io.StringIO(text).readline)
                if token.type == tokenize.COMMENT]
    return docstrings + comments


def mentioned(path: Path) -> list[str]:
    """The dotted project names in ``path``'s documentation, each once, in order."""
    return list(dict.fromkeys(name for text in documentation(path) for name in DOTTED.findall(text)))


def exists(name: str) -> bool:
    """Whether the longest importable prefix of ``name`` is a module holding the rest as attributes."""
    parts = name.split(".")
    for length in range(len(parts), 0, -1):
        module_name = ".".join(parts[:length])
        try:
            found = importlib.import_module(module_name)
            break
        except ModuleNotFoundError as error:      # only the name's own missing prefix; a missing dependency fails
            if error.name is None or not (module_name + ".").startswith(error.name + "."):
                raise
    else:
        return False
    for attribute in parts[length:]:
        if not hasattr(found, attribute):
            return False
        found = getattr(found, attribute)
    return True


def test_names_are_found_in_backticks_and_plain_text_but_not_in_paths_or_words():
    text = ("`lab_modules.claims.Claim` and app.cli.main. Not lab_modules/plants, webapp.x, "
            "python -m app, ./app.py nor my_app.cli")
    assert DOTTED.findall(text) == ["lab_modules.claims.Claim", "app.cli.main"]


def test_exists_follows_modules_then_attributes():
    assert exists("lab_modules.claims") and exists("lab_modules.claims.Claim.holds")
    assert exists("lab_modules.estimators.kalman.KalmanFilter")
    assert not exists("lab_modules.closed_loop")                      # a module that no longer exists
    assert not exists("lab_modules.claims.Claim.no_such_method")
    assert not exists("lab_modules.no_such_package.module")


def test_the_documentation_mentions_names_at_all():
    """The scan reads docstrings, comments and Markdown (else the test below would pass on nothing)."""
    assert sum(len(mentioned(path)) for path in FILES) >= 10


@pytest.mark.parametrize("path", FILES, ids=lambda path: str(path.relative_to(ROOT)))
def test_every_documented_name_exists(path):
    missing = [name for name in mentioned(path) if not exists(name)]
    assert not missing, f"{path.relative_to(ROOT)} names what does not exist: {missing}"


#: A path into the project's source folders (``app/tab/session.py``, ``static/worksheets``)
PATH = re.compile(r"(?<![\w./-])(?:app|lab_modules|tests|static|scripts)/[\w./-]*\w")


def paths_mentioned(path: Path) -> list[str]:
    return list(dict.fromkeys(found for text in documentation(path) for found in PATH.findall(text)))


def test_paths_are_found():
    assert PATH.findall("see `app/tab/session.py`, static/worksheets and ../app/x") == [
        "app/tab/session.py", "static/worksheets"]


@pytest.mark.parametrize("path", FILES, ids=lambda path: str(path.relative_to(ROOT)))
def test_every_documented_path_exists(path):
    """A file or folder named by its path (the layout table, "see app/panels/scope.py") is there."""
    missing = [found for found in paths_mentioned(path) if not (ROOT / found).exists()
               and not any(ROOT.glob(found))]
    assert not missing, f"{path.relative_to(ROOT)} names paths that do not exist: {missing}"
