#!/usr/bin/env bash
# The main job: package the FMU, then run the paper's sweeps through it (report, JSON, CSVs, plots).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo run --release -p fmu-build
cargo run --release --bin thermovia -- sweep --out "${1:-out/sweep}"
