#!/usr/bin/env bash
# Every test: Rust unit/integration tests through the packaged FMU, then the fmpy checks.
# Installs what it needs (libclang for the second importer, the pinned fmpy venv); fails, never
# skips, when fmpy is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-system.sh
scripts/setup-python.sh
cargo run --release -p fmu-build
cargo test --release --workspace
.venv/bin/python -m pytest tests/python -q
