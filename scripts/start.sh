#!/usr/bin/env bash
# Install the lab and start it on its defaults (http://127.0.0.1:8080).
set -euo pipefail
cd "$(dirname "$0")/.."
python -m pip install --quiet -e .
exec python -m app "$@"
