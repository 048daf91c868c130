#!/usr/bin/env bash
# Every test: formatting and lints, the Rust tests through the packaged FMU, then the Python
# importers' checks (fmpy, fmu-manipulation-toolbox, libcosimpy, ecospy). Installs what it needs
# (Debian's libclang-dev and libtbb12, the pinned venv); fails, never skips, when an importer is
# missing.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-system.sh
scripts/setup-python.sh
cargo fmt --all --check
cargo clippy --release --workspace --all-targets --quiet -- -D warnings
cargo run --release -p fmu-build
cargo test --release --workspace
.venv/bin/python -m pytest tests/python -q
