"""The last line of a test run that skipped tests for missing programs (tests/skipped.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.skipped import summary_line

ROOT = Path(__file__).resolve().parents[1]


def test_the_line_names_what_was_skipped_and_the_command_that_installs_it():
    reasons = ["Skipped: Debian's chromium is not installed"] * 28 + \
              ["Skipped: HAProxy is not installed (apt-get install haproxy)"] * 3 + ["Skipped: needs 4 cores"]
    assert summary_line(reasons) == ("Skipped 28 browser tests (no chromium), 3 lecture-hall tests (no haproxy); "
                                     "to run them too: sudo apt-get install chromium haproxy")
    assert summary_line(["Skipped: HAProxy is not installed"]).endswith("sudo apt-get install haproxy")
    assert summary_line(["Skipped: needs 4 cores"]) == ""
    assert summary_line(["Skipped: PostgreSQL is not installed (no initdb/pg_ctl on PATH)"] * 2) == (
        "Skipped 2 PostgreSQL store tests (no postgresql); to run them too: sudo apt-get install postgresql")


def test_a_run_with_skips_ends_with_that_line(tmp_path):
    """A pytest run whose only test is skipped for a missing Chromium ends with the line."""
    (tmp_path / "test_needs_chromium.py").write_text(
        "import pytest\n\n@pytest.mark.skipif(True, reason=\"Debian's chromium is not installed\")\n"
        "def test_page():\n    pass\n")
    (tmp_path / "conftest.py").write_text("from tests.conftest import pytest_unconfigure  # noqa: F401\n")
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True, env={"PYTHONPATH": str(ROOT)}, check=False)
    lines = run.stdout.strip().splitlines()
    assert run.returncode == 0 and "1 skipped" in lines[-2], run.stdout
    assert lines[-1] == "Skipped 1 browser test (no chromium); to run them too: sudo apt-get install chromium"
