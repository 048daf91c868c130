"""Blind calibration against the independent truth model: each scenario writes runs with
tests/truth/truth_model.py (stiffness and damping chosen directly, effects as the Modelica Standard
Library defines them, inertia declared), runs `thermovia calibrate` on them, and compares what the
loop reports with the truth: effects added, their parameters against the truth's (relative error;
"missed" when the loop did not add a true effect, "extra" for one it added that is not there), the
transmission's stiffness and damping per temperature against the truth's (the worst relative error
over temperatures, when the report has `identified`), and the final error against the noise floor
sqrt(σ² + q²/12). Prints a Markdown table; exits 0 whatever the verdicts (it measures, the tests
assert).

  .venv/bin/python tests/truth/blind.py --out out/blind
  .venv/bin/python tests/truth/blind.py --only "clean, moduli ×5" --out /tmp/blind
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
    "clean, moduli ×0.1": ["--stiffness-scale", "0.1"],
    "clean, moduli ×20": ["--stiffness-scale", "20"],
    "clean, multisine": ["--excitation", "multisine"],
    "stribeck 0.02 + 0.03 N·m, 0.05 rad/s": ["--effect", "coulomb_friction=0.02", "--effect", "stribeck=0.03,0.05"],
    "asymmetric friction 0.06/0.03 N·m, 0.02/0.01 N·m·s": ["--effect", "asymmetric_friction=0.06,0.03,0.02,0.01"],
    "constant load 0.1 N·m": ["--effect", "constant_load=0.1"],
    "hardening spring α 100 /rad² (out of library)": ["--effect", "hardening=100"],
    "stiffness with link angle β 5 /rad² (out of library)": ["--effect", "angle_stiffness=5"],
    "jitter 2e-5 of a step": ["--jitter", "2e-5"],
    "gravity 1.25 + coulomb 0.03": ["--effect", "gravity_mgl=1.25", "--effect", "coulomb_friction=0.03"],
    "gravity 1.25 at 0.15 rad + coulomb 0.03": ["--effect", "gravity_mgl=1.25", "--effect", "gravity_offset=0.15",
                                                "--effect", "coulomb_friction=0.03"],
    "link damping 0.02 + gravity 1.25": ["--effect", "link_damping=0.02", "--effect", "gravity_mgl=1.25"],
    "backlash 0.02 + gravity 1.25": ["--effect", "backlash=0.02", "--effect", "gravity_mgl=1.25"],
    "backlash 0.02 + coulomb 0.03": ["--effect", "backlash=0.02", "--effect", "coulomb_friction=0.03"],
    "coulomb 0.03 + link damping 0.02": ["--effect", "coulomb_friction=0.03", "--effect", "link_damping=0.02"],
    "gravity 1.25 + constant load 0.1": ["--effect", "gravity_mgl=1.25", "--effect", "constant_load=0.1"],
    "gravity 1.25 + coulomb 0.03 + backlash 0.02": ["--effect", "gravity_mgl=1.25", "--effect", "coulomb_friction=0.03",
                                                    "--effect", "backlash=0.02"],
    "gravity 1.25 at 0.15 rad + link damping 0.02 + coulomb 0.03": [
        "--effect", "gravity_mgl=1.25", "--effect", "gravity_offset=0.15", "--effect", "link_damping=0.02",
        "--effect", "coulomb_friction=0.03"],
}
# the rest of the pairs of coexisting library effects (issue 18), and a triple with asymmetric friction
STRIBECK = ["--effect", "coulomb_friction=0.02", "--effect", "stribeck=0.03,0.05"]
ASYMMETRIC = ["--effect", "asymmetric_friction=0.06,0.03,0.02,0.01"]
SCENARIOS.update({
    "coulomb 0.03 + constant load 0.1": ["--effect", "coulomb_friction=0.03", "--effect", "constant_load=0.1"],
    "stribeck + backlash 0.02": STRIBECK + ["--effect", "backlash=0.02"],
    "stribeck + gravity 1.25": STRIBECK + ["--effect", "gravity_mgl=1.25"],
    "stribeck + link damping 0.02": STRIBECK + ["--effect", "link_damping=0.02"],
    "stribeck + constant load 0.1": STRIBECK + ["--effect", "constant_load=0.1"],
    "asymmetric friction + backlash 0.02": ASYMMETRIC + ["--effect", "backlash=0.02"],
    "asymmetric friction + gravity 1.25": ASYMMETRIC + ["--effect", "gravity_mgl=1.25"],
    "backlash 0.02 + link damping 0.02": ["--effect", "backlash=0.02", "--effect", "link_damping=0.02"],
    "backlash 0.02 + constant load 0.1": ["--effect", "backlash=0.02", "--effect", "constant_load=0.1"],
    "link damping 0.02 + constant load 0.1": ["--effect", "link_damping=0.02", "--effect", "constant_load=0.1"],
    "asymmetric friction + backlash 0.02 + gravity 1.25": ASYMMETRIC + ["--effect", "backlash=0.02",
                                                                       "--effect", "gravity_mgl=1.25"],
})


def relative(found, true):
    if true == 0:
        return f"{found:.3g} vs 0"
    return f"{found:.3g} vs {true:.3g} ({100 * (found / true - 1):+.0f} %)"


def effect_errors(truth_effects, added):
    """Each true effect's parameters against what the loop added under the same name."""
    found = {e["effect"]: e["parameters"] for e in added}
    parts = []
    for name, params in truth_effects.items():
        if params.get("out_of_library"):
            parts.append(f"{name}: out of library" + (" (loop added " + ", ".join(found) + ")" if found else ""))
        elif name not in found:
            parts.append(f"{name}: missed")
        else:
            parts.append(name + ": " + ", ".join(
                f"{k} {relative(found[name][k], v)}" if k in found[name] else f"{k} not reported"
                for k, v in params.items()))
    parts += [f"{name}: extra" for name in found if name not in truth_effects]
    return "; ".join(parts) or "—"


def transmission_errors(rep, truth):
    """Worst relative error over temperatures of the identified stiffness and damping."""
    ident = rep.get("identified")
    if not ident:
        return "n/a (no `identified` in report)"
    true = {round(r["temperature_c"], 6): (r["stiffness"], r["damping"]) for r in truth["runs"]}
    worst = {}
    for e in ident:
        t = true.get(round(e.get("temperature_c", float("nan")), 6))
        for i, key in enumerate(("stiffness", "damping")):
            if t and isinstance(e.get(key), (int, float)) and t[i]:
                err = e[key] / t[i] - 1
                if abs(err) >= abs(worst.get(key, 0.0)):
                    worst[key] = err
    return ", ".join(f"{'K' if k == 'stiffness' else 'C'} {100 * v:+.0f} %" for k, v in worst.items()) or "n/a"


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
            lines = (run.stderr.strip() or "no message").splitlines()
            rows.append((name, "error: " + lines[-1], "", "", "", "", "", f"{seconds:.1f}"))
            continue
        rep = json.loads((out / "report.json").read_text())
        added = ", ".join(f"{e['effect']} {json.dumps(e['parameters'])}" for e in rep["added_effects"]) or "none"
        rows.append((name, json.dumps(truth["effects"]) if truth["effects"] else "none", added,
                     effect_errors(truth["effects"], rep["added_effects"]), transmission_errors(rep, truth),
                     f"{rep['baseline']['rmse_rad'] / floor:.2f}", f"{rep['final']['rmse_rad'] / floor:.2f}"
                     + (" (unexplained)" if rep.get("unexplained") else ""), f"{seconds:.1f}"))
    print("| scenario | truth effects | added by the loop | effect parameters found vs truth | K, C found vs truth "
          "(worst over temperatures) | baseline / floor | final / floor | s |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")


if __name__ == "__main__":
    main()
