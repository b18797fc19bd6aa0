#!/usr/bin/env bash
# Build the API reference (docs/api) from the docstrings, every warning an error.
#   bash docs/build.sh            # HTML into docs/api/_build/html
# Needs the docs extra: .venv/bin/pip install -e '.[docs]'
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-.venv/bin/python}"
OUT="${1:-docs/api/_build/html}"
"$PY" -m sphinx -W --keep-going -q -b html -d docs/api/_build/doctrees docs/api "$OUT"
echo "API reference: $OUT/index.html"
