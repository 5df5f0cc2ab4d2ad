"""The test run's last line when tests were skipped for a missing system program: what was
skipped and the one command that installs what those tests need (issue 25: a fresh machine
showed 31 skips as nothing but ``s`` marks)."""

from __future__ import annotations

#: (a word of the skip reason, what the tests are, the Debian package that brings the program);
#: a new system requirement is one more line here.
NEEDS = (
    ("chromium", "browser tests", "chromium"),
    ("haproxy", "lecture-hall tests", "haproxy"),
    ("postgresql", "PostgreSQL store tests", "postgresql"),
)


def reason_of(report) -> str:
    """A skipped test report's reason ("Skipped: …" in pytest's (file, line, reason) tuple)."""
    longrepr = report.longrepr
    return longrepr[2] if isinstance(longrepr, tuple) and len(longrepr) == 3 else str(longrepr)


def summary_line(reasons: list[str]) -> str:
    """One line naming the skipped tests by what they need and the command that installs it
    ("" when nothing was skipped for a missing program)."""
    counts = {}
    for reason in reasons:
        for word, kind, package in NEEDS:
            if word in reason.lower():
                counts[(kind, package)] = counts.get((kind, package), 0) + 1
                break
    if not counts:
        return ""
    parts = ", ".join(f"{count} {kind if count > 1 else kind.removesuffix('s')} (no {package})"
                      for (kind, package), count in counts.items())
    packages = " ".join(package for _, package in counts)
    return f"Skipped {parts}; to run them too: sudo apt-get install {packages}"
