"""An independent truth model of a rig like ThermoVIA's, written apart from the FMU and its Rust
code: the motor angle is prescribed (the measured angle drives the model), the output link of
inertia J hangs on a transmission of stiffness K and damping C (per temperature, chosen directly,
not from the FMU's material table), and effects act on the link as the Modelica Standard Library
defines them:

- backlash: ElastoBacklash. With the relative angle φ = θm − θl and half-play b = width/2, the
  spring acts on the part of φ beyond ±b; the damper acts only while in contact and never pulls:
  τ = K(φ − b) + C φ' for φ > b, clipped at ≥ 0 (and symmetric for φ < −b), τ = 0 inside the play.
- Coulomb friction: BearingFriction with a smooth sign, τ_f = Fc tanh(θl'/v_s) (v_s small);
- Stribeck friction: τ_f = (Fc + Fs exp(−(θl'/v_st)²)) tanh(θl'/v_s);
- gravity: τ_g = −mgl sin(θl − offset);
- link damping to ground: τ = −B θl'; constant load: τ = τ_0.

Integration: classical RK4 at a fine fixed step (default 1e-4 s), with the motor angle and speed
given analytically. Measurements: Gaussian noise, then encoder quantisation, then (optionally)
timestamp jitter. Files follow docs/interfaces.md (one CSV per run, `# key=value` metadata).

  .venv/bin/python tests/truth/truth_model.py --out out/truth --effect backlash=0.02 --stiffness-scale 5
"""
import argparse
import json
import math
from pathlib import Path

import numpy as np

ENCODER_QUANTUM = 2 * math.pi / 10000  # 2500 lines × 4 edges per revolution


def link_torque(phi, dphi, v, p):
    """Torque on the link from the transmission and the effects (v = link speed)."""
    k, c = p["stiffness"], p["damping"]
    b = 0.5 * p.get("backlash", 0.0)
    if b > 0.0:
        if phi > b:
            tau = max(k * (phi - b) + c * dphi, 0.0)
        elif phi < -b:
            tau = min(k * (phi + b) + c * dphi, 0.0)
        else:
            tau = 0.0
    else:
        tau = k * phi + c * dphi
    vs = p.get("friction_smoothing", 1e-3)
    fc = p.get("coulomb_friction", 0.0)
    fs = p.get("stribeck_friction", 0.0)
    if fc > 0.0 or fs > 0.0:
        vst = p.get("stribeck_velocity", 0.05)
        tau -= (fc + fs * math.exp(-(v / vst) ** 2)) * math.tanh(v / vs)
    if p.get("gravity_mgl", 0.0) > 0.0:
        tau -= p["gravity_mgl"] * math.sin(p["theta_l"] - p.get("gravity_offset", 0.0))
    tau -= p.get("link_damping", 0.0) * v
    tau += p.get("constant_load", 0.0)
    return tau


def simulate(p, t_end, dt, motor):
    """RK4 of θl, θl' with the motor angle motor(t) -> (angle, speed). Returns the fine time grid
    and the link angle on it. Plain floats: numpy per step would cost more than the arithmetic."""
    n = int(round(t_end / dt))
    th, v = p.get("initial_link_angle", 0.0), 0.0
    out = np.empty(n + 1)
    out[0] = th
    j = p["inertia"]

    def acc(t, th, v):
        m, dm = motor(t)
        p["theta_l"] = th
        return link_torque(m - th, dm - v, v, p) / j

    for i in range(n):
        t = i * dt
        a1 = acc(t, th, v)
        a2 = acc(t + dt / 2, th + dt / 2 * v, v + dt / 2 * a1)
        a3 = acc(t + dt / 2, th + dt / 2 * (v + dt / 2 * a1), v + dt / 2 * a2)
        a4 = acc(t + dt, th + dt * (v + dt / 2 * a2), v + dt * a3)
        th, v = th + dt / 6 * (v + 2 * (v + dt / 2 * a1) + 2 * (v + dt / 2 * a2) + (v + dt * a3)), v + dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        out[i + 1] = th
    return np.arange(n + 1) * dt, out


def write_run(path, meta, columns):
    names = list(columns)
    with open(path, "w", encoding="utf-8") as fh:
        for k, v in meta.items():
            fh.write(f"# {k}={v}\n")
        fh.write(",".join(names) + "\n")
        for row in zip(*(columns[n] for n in names)):
            fh.write(",".join(repr(float(x)) for x in row) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, type=Path, help="folder for the run files and truth.json")
    ap.add_argument("--temperatures", default="22,40,50,60", help="run temperatures, °C (comma-separated)")
    ap.add_argument("--frequencies", default="0.5,1", help="motor frequencies, Hz (comma-separated)")
    ap.add_argument("--stiffness", default="34,20,12,5",
                    help="transmission stiffness per temperature, N·m/rad (comma-separated, one per temperature)")
    ap.add_argument("--damping", default="0.4,0.3,0.2,0.1", help="transmission damping per temperature, N·m·s/rad")
    ap.add_argument("--stiffness-scale", type=float, default=1.0, help="factor on every stiffness")
    ap.add_argument("--inertia", type=float, default=0.018, help="link inertia, kg·m²")
    ap.add_argument("--declare-inertia", action="store_true", help="write link_inertia_kgm2 into the files")
    ap.add_argument("--amplitude", type=float, default=0.3, help="motor amplitude, rad")
    ap.add_argument("--duration", type=float, default=20.0, help="run length, s")
    ap.add_argument("--rate", type=float, default=1000.0, help="sampling rate, Hz")
    ap.add_argument("--dt", type=float, default=1e-4, help="integration step, s (a divisor of the sample period)")
    ap.add_argument("--noise", type=float, default=1e-4, help="sensor noise std before quantisation, rad")
    ap.add_argument("--quantum", type=float, default=ENCODER_QUANTUM, help="encoder step, rad (0: none)")
    ap.add_argument("--jitter", type=float, default=0.0, help="timestamp jitter, fraction of a sample period")
    ap.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                    help="backlash=WIDTH, coulomb_friction=FC, stribeck_friction=FS, gravity_mgl=MGL, "
                         "gravity_offset=RAD, link_damping=B, constant_load=TAU (repeatable)")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args(argv)
    temps = [float(x) for x in a.temperatures.split(",")]
    freqs = [float(x) for x in a.frequencies.split(",")]
    ks = [float(x) * a.stiffness_scale for x in a.stiffness.split(",")]
    cs = [float(x) for x in a.damping.split(",")]
    if not (len(ks) == len(cs) == len(temps)):
        ap.error("--stiffness and --damping need one value per temperature")
    effects = {}
    for e in a.effect:
        name, _, value = e.partition("=")
        effects[name] = float(value)
    rng = np.random.default_rng(a.seed)
    a.out.mkdir(parents=True, exist_ok=True)
    stride = int(round(1.0 / (a.rate * a.dt)))
    truth = {"inertia": a.inertia, "effects": effects, "noise": a.noise, "quantum": a.quantum, "runs": []}
    for temp, k, c in zip(temps, ks, cs):
        for f in freqs:
            w = 2 * math.pi * f
            p = {"stiffness": k, "damping": c, "inertia": a.inertia, **effects}
            t, link = simulate(p, a.duration, a.dt, lambda t: (a.amplitude * math.sin(w * t), a.amplitude * w * math.cos(w * t)))
            ts, ls = t[::stride], link[::stride]
            ms = a.amplitude * np.sin(w * ts)

            def measure(x):
                y = x + rng.normal(0.0, a.noise, x.shape) if a.noise > 0 else x.copy()
                return np.round(y / a.quantum) * a.quantum if a.quantum > 0 else y

            tm = ts + (rng.uniform(-a.jitter, a.jitter, ts.shape) / a.rate if a.jitter > 0 else 0.0)
            name = f"run_{temp:g}C_{f:g}Hz.csv"
            meta = {"temperature_c": temp, "source": "tests/truth/truth_model.py"}
            if a.declare_inertia:
                meta["link_inertia_kgm2"] = a.inertia
            write_run(a.out / name, meta, {"time_s": tm, "motor_angle_rad": measure(ms), "link_angle_rad": measure(ls)})
            truth["runs"].append({"file": name, "temperature_c": temp, "frequency_hz": f, "stiffness": k, "damping": c})
    (a.out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")


if __name__ == "__main__":
    main()
