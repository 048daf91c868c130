#!/usr/bin/env bash
# The MuJoCo example: a three-joint arm with a ThermoVIA joint (the native plugin) at every joint, the touch /
# heat / touch task, its report with plots and off-screen frames in out/mujoco. Installs what it
# needs first (Debian's libosmesa6 for the frames, the pinned venv with mujoco and fmpy) and builds
# the FMU. Extra arguments go to the example (python examples/mujoco/thermovia_mujoco.py --help).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup-system.sh
scripts/setup-python.sh
cargo run --release -p fmu-build
cargo build --release --bin thermovia -p thermovia-mujoco   # the plugin, and `thermovia arm` for the cross-check
.venv/bin/python examples/mujoco/thermovia_mujoco.py --out out/mujoco "$@"
