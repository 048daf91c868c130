#!/usr/bin/env bash
# Creates .venv with the pinned fmpy (tests/python/requirements.txt) unless it is already there.
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ ! -x .venv/bin/python ]] || ! .venv/bin/python -c "import fmpy, pytest, numpy" 2>/dev/null \
   || ! cmp -s tests/python/requirements.txt .venv/.requirements; then
  python3 -m venv .venv
  .venv/bin/pip install --quiet --disable-pip-version-check -r tests/python/requirements.txt
  cp tests/python/requirements.txt .venv/.requirements
fi
