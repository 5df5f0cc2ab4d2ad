#!/usr/bin/env bash
# Install the lab with its test extras and run the whole test suite (browser test included).
set -euo pipefail
cd "$(dirname "$0")/.."
python -m pip install --quiet -e ".[test]"
python -m pytest -q "$@"
