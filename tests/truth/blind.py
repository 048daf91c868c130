"""Blind calibration against the independent truth model: each scenario writes runs with
tests/truth/truth_model.py (stiffness and damping chosen directly, effects as the Modelica Standard
Library defines them, inertia declared), runs `thermovia calibrate` on them, and compares what the
loop reports with the truth: effects added, their parameters, and the final error against the
noise floor sqrt(σ² + q²/12). Prints a Markdown table; exits 0 whatever the verdicts (it measures,
the tests assert).

  .venv/bin/python tests/truth/blind.py --out out/blind
"""
import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parent))
import truth_model  # noqa: E402

SCENARIOS = {
    "clean, moduli ×5": ["--stiffness-scale", "5"],
    "clean, moduli ×0.3": ["--stiffness-scale", "0.3"],
    "backlash 0.02 rad": ["--effect", "backlash=0.02"],
    "coulomb 0.05 N·m": ["--effect", "coulomb_friction=0.05"],
    "gravity 1.25 N·m": ["--effect", "gravity_mgl=1.249"],
    "link damping 0.02": ["--effect", "link_damping=0.02"],
}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "blind")
    ap.add_argument("--thermovia", type=Path, default=ROOT / "target" / "release" / "thermovia")
    ap.add_argument("--only", help="run only scenarios whose name contains this text")
    a = ap.parse_args()
    rows = []
    for name, extra in SCENARIOS.items():
        if a.only and a.only not in name:
            continue
        slug = "".join(ch if ch.isalnum() else "_" for ch in name)
        data, out = a.out / slug / "runs", a.out / slug / "calibration"
        truth_model.main(["--out", str(data), "--declare-inertia", "--duration", "10", *extra])
        truth = json.loads((data / "truth.json").read_text())
        floor = math.sqrt(truth["noise"] ** 2 + truth["quantum"] ** 2 / 12)
        t0 = time.monotonic()
        run = subprocess.run([str(a.thermovia), "calibrate", str(data), "--out", str(out), "--no-plots"],
                             capture_output=True, text=True)
        seconds = time.monotonic() - t0
        if run.returncode != 0:
            rows.append((name, "error: " + run.stderr.strip().splitlines()[-1], "", "", "", f"{seconds:.1f}"))
            continue
        rep = json.loads((out / "report.json").read_text())
        added = ", ".join(f"{e['effect']} {json.dumps(e['parameters'])}" for e in rep["added_effects"]) or "none"
        rows.append((name, json.dumps(truth["effects"]) if truth["effects"] else "none", added,
                     f"{rep['baseline']['rmse_rad'] / floor:.2f}", f"{rep['final']['rmse_rad'] / floor:.2f}"
                     + (" (unexplained)" if rep.get("unexplained") else ""), f"{seconds:.1f}"))
    print("| scenario | truth effects | added by the loop | baseline / floor | final / floor | s |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")


if __name__ == "__main__":
    main()
