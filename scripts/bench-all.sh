#!/usr/bin/env bash
# Every benchmark in one session, so the figures in docs/performance.md are measured together: fmi2DoStep in
# every regime (and the work budget's worst cases), the sweep, the arm co-simulation, the calibration, the
# exponential step's coefficients, the smoothing, and the MuJoCo plugin against the FMU co-simulation. Writes
# out/bench/<name>.txt, each headed by the date and commit.
# Run it on an idle machine: the figures are wall-clock medians.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-python.sh
cargo run --release -p fmu-build
cargo build --release -p thermovia-mujoco
out=out/bench
mkdir -p "$out"
header() { echo "# $(date -u '+%Y-%m-%d %H:%M UTC'), commit $(git rev-parse --short HEAD), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)"; }
run() {
    local name=$1; shift
    echo "== $name: $*"
    { header; "$@"; } 2>&1 | tee "$out/$name.txt"
}
run dostep cargo bench --bench dostep
run dostep-budget env DOSTEP_REGIME=budget cargo bench --bench dostep
run sweep cargo bench --bench sweep
run arm cargo bench --bench arm
run calibrate cargo bench --bench calibrate
run exponential cargo bench --bench exponential
run smoothing cargo bench --bench smoothing
run mujoco .venv/bin/python examples/mujoco/bench_plugin.py --out "$out/mujoco"
echo "bench-all: wrote $out/"
