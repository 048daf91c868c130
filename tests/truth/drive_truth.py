"""An independent truth model of a rigid drive (a servo motor with its load, or a linear axis), written
apart from the FMU and its Rust code, logged as docs/interfaces.md's drive runs:

    M q'' = u − Fv q' − F(q') + L

with M the moving inertia (kg·m², or kg on a linear axis), Fv viscous friction, L a constant load and
F the friction of the chosen law, each as the calibration's effect library defines it:
- Coulomb: F = Fc tanh(q'/v_s);
- Stribeck: F = (Fc + Fs exp(−(q'/v_st)²)) tanh(q'/v_s);
- asymmetric: F = Fc± tanh(q'/v_s) + (Fv± − Fv) q', the levels of the direction of motion.
v_s is a small smoothing speed (1e-3 of the run's peak speed by default): a real contact's friction,
not a numerical device of the FMU.

Drives (`--drive`):
- `motor_torque`: u is logged; torque steps of random level and dwell (open loop: the speed settles
  at (u − Fc)/Fv between steps), or a multisine of torque whose peak drives the body to about the
  peak speed (`multisine_level`).
- `reference`: u = sat(kp (r − q̂) − kd q̂'), computed every controller period from the *measured*
  position q̂ (noise and encoder included, as a real controller sees it), q̂' from the two-sample mean
  difference the interface documents; r is smoothed steps or a multisine. u is logged too.
  Beside it runs the truth's own replay: the same rig and reference with the controller reading the
  simulated position instead (what a calibration that replays the controller can simulate). The
  measurement's rms against it, `replay_rms` in truth.json, is the floor a replay can reach: the
  dither the measured noise drives through the controller is the noise's, no model's.

Integration: RK4 with a fine step (at most 1/4 of the sample period and half the friction's
smoothing time constant), the drive held over
each controller (or logging) period. Measurements: Gaussian noise, then encoder quantisation, then
timestamp jitter and an optional dropout; the logged torque carries its own relative noise.

  .venv/bin/python tests/truth/drive_truth.py --out out/servo --inertia 1e-4 --viscous 5e-5 --coulomb 4e-3
"""
import argparse
import json
import math
from pathlib import Path

import numpy as np


def friction(v, p):
    vs = p["smoothing"]
    s = math.tanh(v / vs)
    if p.get("asymmetric"):
        fcp, fcn, fvp, fvn = p["asymmetric"]
        return (fcp * s + (fvp - p["viscous"]) * v) if v > 0 else (fcn * s + (fvn - p["viscous"]) * v)
    f = p["coulomb"]
    if p["stribeck"]:
        fs, vst = p["stribeck"]
        f += fs * math.exp(-(v / vst) ** 2)
    return f * s


def acceleration(v, u, p):
    return (u - p["viscous"] * v - friction(v, p) + p["load"]) / p["inertia"]


def rk4_hold(q, v, u, p, h, n):
    """n RK4 steps of h with the drive u held."""
    for _ in range(n):
        a1 = acceleration(v, u, p)
        a2 = acceleration(v + h / 2 * a1, u, p)
        a3 = acceleration(v + h / 2 * a2, u, p)
        a4 = acceleration(v + h * a3, u, p)
        q += h / 6 * (v + 2 * (v + h / 2 * a1) + 2 * (v + h / 2 * a2) + (v + h * a3))
        v += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
    return q, v


# the runs' version for the campaign's cache: 2, the torque multisine reaches the peak speed
VERSION = 2
MULTISINE_HZ = [0.3, 0.7, 1.3, 2.9, 5.0]


def excitation(kind, level, duration, rng, floor=0.0):
    """A function of t: random steps (levels floor + (0.2–1)(level − floor), alternating sign, dwell
    0.3–1.5 s: a test engineer's steps break the drive away from rest) or a multisine (five
    components 0.3–5 Hz, random phases, peak ≈ level)."""
    if kind == "steps":
        edges, levels, t, sign = [], [], 0.0, 1.0
        while t < duration:
            edges.append(t)
            levels.append(sign * (floor + (level - floor) * rng.uniform(0.2, 1.0)))
            sign = -sign if rng.uniform() < 0.8 else sign
            t += rng.uniform(0.3, 1.5)
        edges, levels = np.array(edges), np.array(levels)
        return lambda t: float(levels[np.searchsorted(edges, t, side="right") - 1])
    freqs = np.array(MULTISINE_HZ)
    phases = rng.uniform(0, 2 * math.pi, freqs.size)
    amps = multisine_weights()
    amps *= level / amps.sum()
    return lambda t: float(np.sum(amps * np.sin(2 * math.pi * freqs * t + phases)))


def multisine_weights():
    """Each multisine component's relative amplitude, 1/√f."""
    return 1.0 / np.sqrt(np.array(MULTISINE_HZ))


def multisine_level(a, breakaway):
    """The torque multisine's peak that drives the body to about the rig's peak speed: each
    component's speed is its torque over |Fv + i M ω| (the friction's break-away on top). The peak
    friction alone, the steps' level, would leave an inertia-dominated drive far below that speed
    (drive rig 13: 9 rad/s of a drawn 143, under its 15 rad/s Stribeck speed: no Stribeck to see)."""
    freqs = np.array(MULTISINE_HZ)
    amps = multisine_weights()
    mobility = np.sum(amps / amps.sum() / np.abs(a.viscous + 1j * a.inertia * 2 * math.pi * freqs))
    return a.speed / mobility + breakaway


def pd_controller(kp, kd, sat, period):
    """The rig's controller as a function of (reference, position read) -> u, with its own state:
    u = sat(kp (r − q) − kd q'), q' from qf(k) = (q(k) + q(k−1))/2, q'(k) = (qf(k) − qf(k−1))/T
    (0 on the first call)."""
    prev_q, prev_qf = None, None

    def step(r, q):
        nonlocal prev_q, prev_qf
        qf = q if prev_q is None else 0.5 * (q + prev_q)
        dq = 0.0 if prev_qf is None else (qf - prev_qf) / period
        prev_q, prev_qf = q, qf
        return max(-sat, min(sat, kp * (r - q) - kd * dq))
    return step


def smooth_reference(kind, amplitude, duration, rng, smoothing):
    """Reference of a position servo: steps smoothed by tanh over `smoothing` s, or a multisine."""
    if kind == "multisine":
        return excitation("multisine", amplitude, duration, rng)
    raw = excitation("steps", amplitude, duration, rng)
    edges = [0.0]
    t = 0.0
    while t < duration:  # the step times, found by scanning (the step function hides them)
        t2 = t + 1e-3
        if raw(t2) != raw(t):
            edges.append(t2)
        t = t2
    levels = [raw(e) for e in edges]

    def r(t):
        x = levels[0]
        for e, a, b in zip(edges[1:], levels, levels[1:]):
            x += 0.5 * (b - a) * (1.0 + math.tanh((t - e) / smoothing))
        return x
    return r


def write_run(path, meta, columns):
    with open(path, "w", encoding="utf-8") as fh:
        for k, v in meta.items():
            fh.write(f"# {k}={v}\n")
        fh.write(",".join(columns) + "\n")
        for row in zip(*columns.values()):
            fh.write(",".join(repr(float(x)) for x in row) + "\n")


def parse_args(argv=None):
    """The truth's arguments (argparse's exit on a bad one)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True, help="folder for run_K.csv and truth.json")
    ap.add_argument("--axis", choices=["rotary", "linear"], default="rotary")
    ap.add_argument("--drive", choices=["motor_torque", "reference"], default="motor_torque")
    ap.add_argument("--excitation", choices=["steps", "multisine"], default="steps")
    ap.add_argument("--inertia", type=float, default=1e-4, help="moving inertia, kg·m² (kg on a linear axis)")
    ap.add_argument("--viscous", type=float, default=5e-5, help="viscous friction, N·m·s/rad (N·s/m)")
    ap.add_argument("--coulomb", type=float, default=0.0, help="Coulomb friction, N·m (N)")
    ap.add_argument("--stribeck", type=float, nargs=2, metavar=("FS", "VST"), help="Stribeck excess and its speed")
    ap.add_argument("--asymmetric", type=float, nargs=4, metavar=("FC+", "FC-", "FV+", "FV-"),
                    help="direction-wise Coulomb and viscous levels (replace --coulomb and --viscous)")
    ap.add_argument("--load", type=float, default=0.0, help="constant load on the body, N·m (N), added to the drive")
    ap.add_argument("--speed", type=float, default=200.0, help="peak speed the drive reaches, rad/s (m/s)")
    ap.add_argument("--amplitude", type=float, default=2.0, help="reference amplitude (drive=reference), rad (m)")
    ap.add_argument("--reference-smoothing", type=float, default=0.05,
                    help="time scale T of each reference step's tanh, s (peak speed amplitude/2T)")
    ap.add_argument("--kp", type=float, help="controller gain per position error (default: from the inertia, 20 Hz)")
    ap.add_argument("--kd", type=float, help="controller gain per speed (default: damping ratio 0.7)")
    ap.add_argument("--saturation", type=float, help="controller output limit (default: 3× the peak friction torque)")
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--duration", type=float, nargs="+", default=[20.0], help="seconds per run (one, or one per run)")
    ap.add_argument("--rate", type=float, default=1000.0, help="sample rate, Hz")
    ap.add_argument("--noise", type=float, default=1e-5, help="position noise, rad (m)")
    ap.add_argument("--quantum", type=float, default=2 * math.pi / 1e4, help="encoder step, rad (m)")
    ap.add_argument("--torque-noise", type=float, default=0.01, help="relative noise of the logged drive")
    ap.add_argument("--jitter", type=float, default=0.0, help="timestamp jitter, fraction of the period (< 0.5)")
    ap.add_argument("--dropout", type=float, default=0.0, help="seconds lost once per run")
    ap.add_argument("--declare-inertia", action="store_true")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args(argv)
    if not 0.0 <= a.jitter < 0.5:
        ap.error("--jitter must be in [0, 0.5)")
    return a


def main(argv=None):
    a = parse_args(argv)
    rng = np.random.default_rng(a.seed)
    lin = a.axis == "linear"
    pos, force = ("motor_position_m", "motor_force_n") if lin else ("motor_angle_rad", "motor_torque_nm")
    p = {"inertia": a.inertia, "viscous": a.viscous, "coulomb": a.coulomb, "stribeck": a.stribeck,
         "asymmetric": a.asymmetric, "load": a.load, "smoothing": 1e-3 * a.speed}
    # the friction at rest to break away from, and at peak speed
    breakaway = max([a.coulomb] + (a.asymmetric[:2] if a.asymmetric else [])) + (a.stribeck[0] if a.stribeck else 0.0)
    peak_friction = a.viscous * a.speed + breakaway
    period = 1.0 / a.rate
    # the friction's smoothing is the stiffest rate: λ = (Fv + peak Coulomb / v_s) / M; h ≤ 0.5/λ
    stiff = (a.viscous + (peak_friction + (a.stribeck[0] if a.stribeck else 0.0)) / p["smoothing"]) / a.inertia
    sub = max(4, math.ceil(period * stiff / 0.5))
    h = period / sub
    a.out.mkdir(parents=True, exist_ok=True)
    for old in a.out.glob("run_*.csv"):
        old.unlink()
    truth = {"axis": a.axis, "drive": a.drive, "inertia": a.inertia, "viscous": a.viscous, "coulomb": a.coulomb,
             "stribeck": a.stribeck, "asymmetric": a.asymmetric, "constant_load": a.load,
             "smoothing_speed": p["smoothing"], "noise": a.noise, "quantum": a.quantum, "rate_hz": a.rate,
             "jitter": a.jitter, "dropout_s": a.dropout, "seed": a.seed, "runs": []}
    wn = 2 * math.pi * 20.0
    kp = a.kp if a.kp is not None else a.inertia * wn ** 2
    kd = a.kd if a.kd is not None else 2 * 0.7 * a.inertia * wn
    # the drive's limit: 1.5× what the peak speed's friction and a reference step's acceleration need
    # (a step of the amplitude smoothed over T accelerates at up to ≈ amplitude / T²)
    sat = a.saturation if a.saturation is not None else \
        1.5 * (peak_friction + a.inertia * a.amplitude / a.reference_smoothing ** 2)
    for r in range(a.runs):
        dur = a.duration[r % len(a.duration)]
        n = int(round(dur * a.rate))
        if a.drive == "motor_torque":
            # the test signal holds the load off (a feed-forward), so the drive reverses and friction
            # shows both its signs: one sign alone is a constant torque, the same as the load
            level = peak_friction if a.excitation == "steps" else multisine_level(a, breakaway)
            shape = excitation(a.excitation, level, dur, rng, floor=breakaway)
            u_of_t = (lambda f: lambda t: f(t) - a.load)(shape)
            ref = None
        else:
            ref = smooth_reference(a.excitation, a.amplitude, dur, rng, a.reference_smoothing)
        q, v = 0.0, 0.0
        ts = np.arange(n + 1) * period
        meas = np.empty(n + 1)
        us = np.empty(n + 1)
        control = pd_controller(kp, kd, sat, period)
        replay_control = pd_controller(kp, kd, sat, period)  # the replay: on the simulated position
        q2, v2 = 0.0, 0.0
        replay = np.empty(n + 1)
        for k, t in enumerate(ts):
            qm = q + rng.normal(0.0, a.noise)
            qm = a.quantum * round(qm / a.quantum) if a.quantum > 0 else qm
            meas[k] = qm
            if ref is None:
                u = u_of_t(t)
            else:
                r_t = ref(t)
                u = control(r_t, qm)
                replay[k] = q2
                q2, v2 = rk4_hold(q2, v2, replay_control(r_t, q2), p, h, sub)
            us[k] = u
            q, v = rk4_hold(q, v, u, p, h, sub)
        logged_u = us * (1.0 + a.torque_noise * rng.normal(size=us.size))
        tm = ts + (rng.uniform(-a.jitter, a.jitter, ts.shape) * period if a.jitter > 0 else 0.0)
        keep = np.ones(ts.shape, bool)
        run = {"file": f"run_{r}.csv", "duration_s": dur}
        if a.dropout > 0:
            start = rng.uniform(0.25, 0.75 - a.dropout / dur) * dur
            keep = (ts < start) | (ts >= start + a.dropout)
            run["dropout_s"] = [float(start), float(start + a.dropout)]
        meta = {"axis": a.axis, "transmission": "rigid", "drive": a.drive, "temperature_c": 22}
        if a.declare_inertia:
            meta["inertia_kg" if lin else "link_inertia_kgm2"] = a.inertia
        columns = {"time_s": tm[keep], pos: meas[keep], force: logged_u[keep]}
        if ref is not None:
            meta.update(controller_kp=kp, controller_kd=kd, controller_saturation=sat, controller_period_s=period)
            columns = {"time_s": tm[keep], pos: meas[keep],
                       ("reference_position_m" if lin else "reference_angle_rad"): [ref(t) for t in ts[keep]],
                       force: logged_u[keep]}
        if ref is not None:
            run["replay_sse"] = float(np.sum((meas[keep] - replay[keep]) ** 2))
            run["samples"] = int(keep.sum())
        write_run(a.out / run["file"], meta, columns)
        truth["runs"].append(run)
    truth["controller"] = {"kp": kp, "kd": kd, "saturation": sat} if a.drive == "reference" else None
    if a.drive == "reference":
        truth["replay_rms"] = math.sqrt(sum(r["replay_sse"] for r in truth["runs"]) /
                                        sum(r["samples"] for r in truth["runs"]))
    (a.out / "truth.json").write_text(json.dumps(truth, indent=1) + "\n")


if __name__ == "__main__":
    main()
