#!/usr/bin/env bash
# Install the lab with its test extras and run the whole test suite (browser test included).
# Without an active virtual environment, the lab gets its own in .venv (a system
# Python on Debian or Ubuntu refuses global installs).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${VIRTUAL_ENV:-}" ]; then
    [ -x .venv/bin/python ] || python3 -m venv .venv
    PYTHON=.venv/bin/python
else
    PYTHON=python
fi
"$PYTHON" -m pip install --quiet -e ".[test]"
"$PYTHON" -m pytest -q "$@"
