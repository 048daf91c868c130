"""The calibration loop's proving ground: device rigs drawn at random, seeded, from the independent
truth model (tests/truth/truth_model.py, written apart from the FMU), each calibrated blind by
`thermovia calibrate` and scored against its truth.

A rig draws (every draw from the rig's own seed):
- the link inertia 0.2–5× the paper's bench (0.018 kg·m²), the link's natural frequency 2–50× the
  highest excitation frequency, which sets the stiffness (kept within 0.3–10× the bench's 34 N·m/rad),
  a damping ratio 0.05–0.3; 1–4 temperatures, the stiffness falling with temperature as the PCL's;
- the excitation: one sine per run at 0.2–5 Hz (one or two frequencies), a multisine, or steps;
- the logger: 200 Hz–5 kHz (at least 10 samples per period of the natural frequency), runs of 5–60 s,
  noise 1e-5–1e-3 rad, encoders of 1k–100k counts per turn, timestamp jitter up to ±20 % of the period
  on half the rigs, a dropout of up to 0.5 s per run on a third;
- on a third of the rigs, a drifting temperature: each run's thermocouple heats by 1–8 K through the run
  (a first-order approach, time constant 0.3–3× the run), and K and C follow the paper's device's shape in
  temperature (tests/truth/truth_model.py), the rig's K and C holding at the drift's midpoint; on half of
  those, a thermal lag of the PCL behind the thermocouple, sized as every effect is (below), where the drift
  lets it move the link that far;
- 0–3 effects of the library with sizes drawn against the rig's noise floor and stiffness (every effect
  moves the link by 20× the floor to a tenth of the amplitude), pairs and triples included; or, on a share of the rigs, an effect
  outside the library (a stiffness that depends on the link's angle).

A rig in the library passes when the added effects are the truth's set, every parameter within 10 %,
the transmission's K and C within 10 % at every temperature, the final RMSE ≤ 1.2× its floor and the
residual is not flagged unexplained. A rig outside the library passes when it is flagged unexplained or
explained to ≤ 1.2× its floor. The floor is the larger of the link sensor's √(σ² + q²/12) and the rms of
the measured link against the truth's own replay driven by the logged motor angle on the logged times
(truth_model.replay): no model driven by that log does better, as its motor encoder's error and the
timestamps' jitter move the model too (while a coarse encoder holds still, its reading sits up to half a
count off, and the link's reading is off again: √2 × the sensor's floor).

Drive rigs come from a second independent truth model (tests/truth/drive_truth.py): a rigid servo or
axis, rotary from 1e-5 to 1e-2 kg·m² or linear from 1 to 100 kg, torque-driven (open loop: torque steps
or a multisine) or reference-driven (a PD controller with saturation on the measured position), viscous
friction with a mechanical time constant M/Fv of 0.2–5 s, Coulomb friction 0.1–2× the viscous torque at
peak speed, and 0–2 more library effects (Stribeck, asymmetric levels) and a constant load on half; the
logger as above (200 Hz–5 kHz, 2–8 runs of 5–30 s and unequal lengths, jitter, dropouts). A drive rig
passes with the truth's effect set, the inertia, the viscous and every friction level within 10 %, and
not flagged unexplained; a reference-driven one also within 1.2× its floor: the larger of the measurement
floor and the rms of the measurement against the truth's own replay (its controller reading the simulated
position, as a calibration's replay must: the dither the measured noise drives through the rig's controller
is no model's to predict). (A torque-driven rig runs open loop: the logged torque's own noise integrates
into the position, so its floor is not the encoder's, and it is judged on the parameters.)

  .venv/bin/python tests/truth/campaign.py --rigs 300 --drive-rigs 100 --out out/campaign   # the benchmark
  .venv/bin/python tests/truth/campaign.py --ci --out out/campaign-ci             # the CI subset
"""
import argparse
import concurrent.futures
import json
import math
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import drive_truth  # noqa: E402
import truth_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
THERMOVIA = ROOT / "target" / "release" / "thermovia"
BENCH_K = 34.0  # N·m/rad, the truth model's default stiffness at 22 °C
BENCH_J = 0.018  # kg·m²
TEMPERATURES = (22.0, 40.0, 50.0, 60.0)
K_SHAPE = (1.0, 20 / 34, 12 / 34, 5 / 34)  # the stiffness's fall with temperature, as the PCL's
RATES = (200, 250, 400, 500, 1000, 2000, 2500, 5000)  # divisors of the truth model's 1e-4 s step
# sample budget of the CI subset: the first rigs whose runs add up to at most this many samples
CI_RIGS, CI_SAMPLES = 30, 60_000
CI_DRIVE_RIGS = 10
DRIFT_STREAM = 1  # the second key of a rig's drift draws (`draw`)


def log_uniform(rng, lo, hi):
    return math.exp(rng.uniform(math.log(lo), math.log(hi)))


def lag_shift(lag, drift, drift_tau, duration, temps, ks, cs, j, w, amplitude):
    """How far a thermal lag moves the link, rad, beyond what each temperature's own K and C take in:
    the link's response θl = H θm, H = Z/(Z − Jω²) with Z = K + iωC, changed by δZ(t), the PCL's K and C
    behind the thermocouple's over the run, less its mean over the run (a lag that only offsets the
    temperature is a change of K and C), |δθl| = amplitude Jω² |δZ| / |Z − Jω²|², at the top frequency w;
    its rms over the run, at the rig's most telling temperature (quasi-static: the lag is slow beside
    the motion)."""
    worst = 0.0
    shape = truth_model.transmission_shape
    times = np.linspace(0.0, duration, 401)
    for temp, k, c in zip(temps, ks, cs):
        run = truth_model.heating(temp, drift, duration, drift_tau)
        k0, c0 = shape(temp)
        dz = []
        for t in times:
            (kl, cl), (kh, ch) = shape(truth_model.pcl_temperature(run, t, lag)), shape(truth_model.housing_temperature(run, t))
            dz.append(complex(k * (kl - kh) / k0, w * c * (cl - ch) / c0))
        dz = np.array(dz)
        varying = math.sqrt(float(np.mean(np.abs(dz - dz.mean()) ** 2)))
        worst = max(worst, amplitude * j * w * w * varying / abs(complex(k - j * w * w, w * c)) ** 2)
    return worst


def lag_for(rng, drift, drift_tau, duration, temps, ks, cs, j, w, amplitude, lo, hi):
    """A thermal lag that moves the link (`lag_shift`: the rms of what K and C do not take in) by a size
    drawn as every effect's is (`lo`–`hi`, log-uniform), found by bisection on its time constant up to
    the heating's own or the run's; 0 where even that moves it by less than `lo` (a drift through the
    flat of the PCL's curve hides any lag)."""
    target = log_uniform(rng, lo, hi)
    shift = lambda lag: lag_shift(lag, drift, drift_tau, duration, temps, ks, cs, j, w, amplitude)  # noqa: E731
    top = min(drift_tau, duration)
    longest = shift(top)
    if longest < lo:
        return 0.0
    if longest <= target:
        return top
    a, b = 1e-3 * top, top
    for _ in range(40):
        mid = math.sqrt(a * b)
        a, b = (mid, b) if shift(mid) < target else (a, mid)
    return math.sqrt(a * b)


def draw(seed):
    """One rig: the truth model's arguments, the expected effects and what the scorer needs."""
    rng = np.random.default_rng(seed)
    excitation = rng.choice(["sine", "sine", "sine", "multisine", "steps"])
    f = log_uniform(rng, 0.2, 5.0) if excitation == "sine" else 1.0
    freqs = [f] if rng.uniform() < 0.5 or excitation != "sine" else [f, min(2 * f, 5.0)]
    f_top = max(freqs) if excitation == "sine" else (3.0 if excitation == "multisine" else 1.0 / (2 * math.pi * 0.05))
    j = BENCH_J * log_uniform(rng, 0.2, 5.0)
    for _ in range(100):
        ratio = log_uniform(rng, 2.0, 50.0)
        k = j * (2 * math.pi * ratio * f_top) ** 2
        if 0.3 * BENCH_K <= k <= 10 * BENCH_K:
            break
    else:
        k = min(max(k, 0.3 * BENCH_K), 10 * BENCH_K)
    f_n = math.sqrt(k / j) / (2 * math.pi)
    n_temps = int(rng.integers(1, 5))
    picks = sorted(rng.choice(4, size=n_temps, replace=False))
    temps = [TEMPERATURES[i] for i in picks]
    ks = [k * K_SHAPE[i] for i in picks]
    zeta = rng.uniform(0.05, 0.3)
    cs = [2 * zeta * math.sqrt(kk * j) for kk in ks]
    rate = int(rng.choice([r for r in RATES if r >= 10 * max(f_n, f_top)] or [RATES[-1]]))
    duration = round(log_uniform(rng, 5.0, 60.0), 1)
    if excitation == "multisine":
        duration = 5.0 * max(1, round(duration / 5.0))  # whole cycles of every component
    noise = log_uniform(rng, 1e-5, 1e-3)
    counts = log_uniform(rng, 1e3, 1e5)
    quantum = 2 * math.pi / counts
    floor = math.sqrt(noise ** 2 + quantum ** 2 / 12)
    amplitude = rng.uniform(0.1, 0.5)
    jitter = rng.uniform(0.0, 0.2) if rng.uniform() < 0.5 else 0.0
    dropout = rng.uniform(0.05, 0.5) if rng.uniform() < 1 / 3 and duration >= 5.0 else 0.0
    # effects, sized by how far they move the link against the softest stiffness: from 20× the floor
    # (visible) to a tenth of the amplitude (an effect, not the whole motion)
    k_soft, w = min(ks), 2 * math.pi * f_top
    hi = 0.1 * amplitude
    lo = min(20.0 * floor, 0.5 * hi)
    deflection = lambda: log_uniform(rng, lo, hi)  # noqa: E731
    size = lambda: deflection() * k_soft  # noqa: E731 (a torque)
    outside = rng.uniform() < 0.15
    args, expected = [], {}
    if outside:
        beta = rng.uniform(0.5, 2.0) / amplitude ** 2
        args += ["--effect", f"angle_stiffness={beta}"]
    else:
        n_effects = int(rng.choice([0, 1, 1, 2, 2, 3]))
        friction = rng.choice(["coulomb", "stribeck", "asymmetric", None])
        others = list(rng.permutation(["backlash", "gravity", "link_damping", "constant_load"]))
        chosen = []
        if n_effects and friction is not None:
            chosen.append(str(friction))
        chosen += [str(o) for o in others][: n_effects - len(chosen)]
        if "asymmetric" in chosen:  # asymmetric friction carries its own viscous levels and offset
            chosen = [c for c in chosen if c not in ("link_damping", "constant_load")]
        for e in chosen:
            if e == "coulomb":
                fc = size()
                args += ["--effect", f"coulomb_friction={fc}"]
                expected["coulomb_friction"] = {"torque_nm": fc}
            elif e == "stribeck":
                fc, fs, vst = size(), size(), rng.uniform(0.05, 0.3) * amplitude * w
                args += ["--effect", f"coulomb_friction={fc}", "--effect", f"stribeck={fs},{vst}"]
                expected["coulomb_friction"] = {"torque_nm": fc}
                expected["stribeck_friction"] = {"torque_nm": fs, "velocity": vst}
            elif e == "asymmetric":
                fp, fn_ = size(), size()
                bp, bn = size() / (amplitude * w), size() / (amplitude * w)
                args += ["--effect", f"asymmetric_friction={fp},{fn_},{bp},{bn}"]
                expected["asymmetric_friction"] = {"coulomb_positive": fp, "coulomb_negative": fn_,
                                                   "viscous_positive": bp, "viscous_negative": bn}
            elif e == "backlash":
                width = deflection()
                args += ["--effect", f"backlash={width}"]
                expected["backlash"] = {"width_rad": width}
            elif e == "gravity":
                mgl = log_uniform(rng, 0.05, 1.0) * amplitude * k_soft
                offset = rng.choice([0.0, rng.uniform(-0.3, 0.3)])
                args += ["--effect", f"gravity_mgl={mgl}", "--effect", f"gravity_offset={offset}"]
                expected["gravity"] = {"mgl_nm": mgl, "offset_rad": float(offset)}
            elif e == "link_damping":
                b = size() / (amplitude * w)
                args += ["--effect", f"link_damping={b}"]
                expected["link_damping"] = {"damping_nms": b}
            elif e == "constant_load":
                tau = size() * rng.choice([-1.0, 1.0])
                args += ["--effect", f"constant_load={tau}"]
                expected["constant_load"] = {"torque_nm": tau}
    # a drifting thermocouple on a third of the rigs (a heating run, K and C following the PCL's shape),
    # drawn from a stream of its own, so every draw above stays what it was before drift was drawn
    drift_rng = np.random.default_rng([seed, DRIFT_STREAM])
    drift = drift_rng.uniform(1.0, 8.0) if drift_rng.uniform() < 1 / 3 else 0.0
    drift_tau = log_uniform(drift_rng, 0.3, 3.0) * duration
    lag = 0.0
    if drift:
        args += ["--drift", repr(drift), "--drift-time-constant", repr(drift_tau)]
        if not outside and drift_rng.uniform() < 0.5:
            lag = lag_for(drift_rng, drift, drift_tau, duration, temps, ks, cs, j, w, amplitude, lo, hi)
        if lag:
            args += ["--effect", f"thermal_lag={lag!r}"]
            expected["thermal_lag"] = {"time_constant_s": lag}
    truth_args = [
        "--declare-inertia", "--replay", "--seed", str(seed), "--excitation", str(excitation),
        "--temperatures", ",".join(f"{t:g}" for t in temps),
        "--frequencies", ",".join(f"{x:.4g}" for x in freqs) if excitation == "sine" else ",".join("1" for _ in freqs),
        "--stiffness", ",".join(repr(x) for x in ks), "--damping", ",".join(repr(x) for x in cs),
        "--inertia", repr(j), "--amplitude", repr(amplitude), "--duration", repr(duration),
        "--rate", str(rate), "--noise", repr(noise), "--quantum", repr(quantum),
        "--jitter", repr(jitter), "--dropout", repr(dropout), *args,
    ]
    n_effects = len(expected)
    klass = "outside library" if outside else f"{n_effects} effect{'s' if n_effects != 1 else ''}"
    samples = int(len(temps) * len(freqs) * duration * rate)
    return {
        "seed": seed, "class": klass, "truth_args": truth_args, "expected": expected, "outside": outside,
        "floor": floor, "samples": samples,
        "rig": {"inertia": j, "stiffness_22c_equivalent": k, "natural_frequency_hz": f_n, "zeta": zeta,
                "temperatures": temps, "excitation": str(excitation), "frequencies_hz": freqs, "rate_hz": rate,
                "duration_s": duration, "amplitude_rad": amplitude, "noise": noise, "counts_per_turn": counts, "jitter": jitter,
                "dropout_s": dropout, "drift_k": drift, "drift_time_constant_s": drift_tau if drift else None,
                "thermal_lag_s": lag},
    }


def draw_drive(seed):
    """One drive rig: drive_truth's arguments, the expected effects and parameters."""
    rng = np.random.default_rng(10_000_019 * seed + 7)  # apart from the device rigs' streams
    linear = rng.uniform() < 0.3
    m = log_uniform(rng, 1.0, 100.0) if linear else log_uniform(rng, 1e-5, 1e-2)
    drive = str(rng.choice(["motor_torque", "reference"]))
    excitation = str(rng.choice(["steps", "multisine"]))
    speed = log_uniform(rng, 0.05, 2.0) if linear else log_uniform(rng, 5.0, 300.0)
    fv = m / log_uniform(rng, 0.2, 5.0)
    # a reference step's time scale: 0.05 s, longer where the drive's force would pass 2 kN (N or N·m)
    smoothing = max(0.05, 1.5 * m * 2 * speed / 2000.0)
    fc = fv * speed * log_uniform(rng, 0.1, 2.0)
    quantum = log_uniform(rng, 1e-7, 1e-5) if linear else 2 * math.pi / log_uniform(rng, 1e3, 1e5)
    noise = log_uniform(rng, 1e-7, 1e-5) if linear else log_uniform(rng, 1e-5, 1e-3)
    rate = int(rng.choice(RATES))
    n_runs = int(rng.integers(2, 9))
    durations = [round(log_uniform(rng, 5.0, 30.0), 1) for _ in range(n_runs)]
    jitter = rng.uniform(0.0, 0.2) if rng.uniform() < 0.5 else 0.0
    dropout = rng.uniform(0.05, 0.5) if rng.uniform() < 1 / 3 else 0.0
    args = ["--axis", "linear" if linear else "rotary", "--drive", drive, "--excitation", excitation,
            "--inertia", repr(m), "--speed", repr(speed), "--amplitude", repr(2 * smoothing * speed),
            "--reference-smoothing", repr(smoothing), "--runs", str(n_runs),
            "--duration", *[repr(d) for d in durations], "--rate", str(rate), "--noise", repr(noise),
            "--quantum", repr(quantum), "--jitter", repr(jitter), "--dropout", repr(dropout), "--seed", str(seed)]
    expected = {"coulomb_friction": {"torque_nm": fc}}
    params = {"inertia": m}
    extra = str(rng.choice(["none", "none", "stribeck", "asymmetric"]))
    if extra == "asymmetric":
        split_c, split_v = rng.uniform(0.1, 0.5), rng.uniform(0.1, 0.5)
        levels = [fc * (1 + split_c), fc * (1 - split_c), fv * (1 + split_v), fv * (1 - split_v)]
        args += ["--viscous", repr(fv), "--asymmetric", *[repr(x) for x in levels]]
        expected["asymmetric_friction"] = dict(zip(
            ["coulomb_positive", "coulomb_negative", "viscous_positive", "viscous_negative"], levels))
    else:
        args += ["--viscous", repr(fv), "--coulomb", repr(fc)]
        params["viscous_friction"] = fv
        if extra == "stribeck":
            fs, vst = fc * rng.uniform(0.5, 1.5), speed * rng.uniform(0.05, 0.2)
            args += ["--stribeck", repr(fs), repr(vst)]
            expected["stribeck_friction"] = {"torque_nm": fs, "velocity": vst}
    if rng.uniform() < 0.5:
        load = float(fc * rng.uniform(0.2, 1.0) * rng.choice([-1.0, 1.0]))
        args += [f"--load={load!r}"]  # one token: argparse reads "-5e-05" alone as an option
        params["constant_load"] = load
    klass = f"drive {'linear' if linear else 'rotary'}, {'torque' if drive == 'motor_torque' else 'reference'}"
    if drive == "reference":
        # the controller at 20 Hz bandwidth needs 10 samples per its period
        rate = max(rate, 400)
        args[args.index("--rate") + 1] = str(rate)
    floor = math.sqrt(noise ** 2 + quantum ** 2 / 12)
    samples = int(sum(durations) * rate)
    return {"seed": seed, "class": klass, "kind": "drive", "truth_args": args, "expected": expected, "params": params,
            "outside": False, "floor": floor, "samples": samples,
            "rig": {"axis": "linear" if linear else "rotary", "drive": drive, "inertia": m, "viscous": fv,
                    "coulomb": fc, "peak_speed": speed, "excitation": excitation, "rate_hz": rate,
                    "durations_s": durations, "noise": noise, "quantum": quantum, "jitter": jitter,
                    "dropout_s": dropout, "extra": extra}}


def drive_forms(report):
    """The drive report's (effects, final parameters) as found, then in each equivalent form it
    declares (`equivalent_forms`, the device's rules: the drive's constant load is a baseline
    parameter, and its library counts asymmetric friction over Coulomb friction, their mean)."""
    found = {e["effect"]: e["parameters"] for e in report.get("added_effects", [])}
    final = {p["name"]: p["value"] for p in report["parameters"]["final"]}
    forms = [(found, final, False)]
    for form in report.get("equivalent_forms", []):
        a = found.get("asymmetric_friction", {})
        vp, vn = a.get("viscous_positive", 0.0), a.get("viscous_negative", 0.0)
        if "asymmetric_friction" in form["found"] and "asymmetric_friction" not in form["equivalent"] \
                and abs(vp - vn) > 0.1 * abs(vp + vn) / 2:
            continue  # symmetric Coulomb friction leaves this viscous asymmetry unexplained
        effects = {k: v for k, v in found.items() if k not in form["found"]}
        effects.update(form["equivalent"])
        params = dict(final)
        if "constant_load" in form["found"] or "constant_load" in effects:
            params["constant_load"] = effects.pop("constant_load", {}).get("torque_nm", 0.0)
        if "asymmetric_friction" in form["equivalent"]:
            a = form["equivalent"]["asymmetric_friction"]
            effects["coulomb_friction"] = {"torque_nm": 0.5 * (a["coulomb_positive"] + a["coulomb_negative"])}
        effects.pop("link_damping", None)  # the drive's viscous friction, a baseline parameter
        forms.append((effects, params, True))
    return forms


def score_drive(rig, report):
    """(passed, reasons) of one calibrated drive rig against its truth: in the form the report found,
    else in an equivalent form it declares (which of two forms the runs cannot tell apart the truth
    used is a coin; `rig["equivalent_form"]` says a pass came that way)."""
    first = None
    for found, final, equivalent in drive_forms(report):
        passed, why = score_drive_form(rig, report, found, final)
        rig["equivalent_form"] = equivalent
        if passed:
            return passed, why
        first = first or why
    rig["equivalent_form"] = False
    return False, first


def score_drive_form(rig, report, found, final):
    """(passed, reasons) of one form of a drive report's effects and parameters."""
    why = []
    if set(found) != set(rig["expected"]):
        why.append(f"effects {sorted(found)} ≠ truth {sorted(rig['expected'])}")
    expected, params = rig["expected"], rig["params"]
    if "asymmetric_friction" in found and "asymmetric_friction" in expected:
        # while the drive moves, a load L and friction F+ forward, F− back act as F+ − L and F− + L:
        # the runs show those two, not how the truth split them (interfaces.md, equivalent forms)
        def folded(levels, load):
            return dict(levels, coulomb_positive=levels["coulomb_positive"] - load,
                        coulomb_negative=levels["coulomb_negative"] + load)
        found = dict(found, asymmetric_friction=folded(found["asymmetric_friction"], final.get("constant_load", 0.0)))
        expected = dict(expected, asymmetric_friction=folded(expected["asymmetric_friction"],
                                                             params.get("constant_load", 0.0)))
        params = {k: v for k, v in params.items() if k != "constant_load"}
    checks = [(f"{e}.{k}", v, found.get(e, {}).get(k)) for e, ps in expected.items() for k, v in ps.items()]
    checks += [(k, v, final.get(k)) for k, v in params.items()]
    for name, value, got in checks:
        if got is None:
            continue
        # a constant load is judged against the friction it sits beside (it may be small)
        scale = abs(value) if name != "constant_load" else rig["rig"]["coulomb"]
        if abs(got - value) > 0.1 * scale:
            why.append(f"{name} = {got:.4g}, truth {value:.4g}")
    ratio = final_rmse(report) / rig["floor"]
    if rig["rig"]["drive"] == "reference" and ratio > 1.2:
        why.append(f"final {ratio:.2f}× the floor")
    if report.get("unexplained"):
        why.append("flagged unexplained")
    return not why, why


def final_rmse(report):
    """The final position RMSE in the file's unit (device reports say rmse_rad, drive reports rmse)."""
    return report["final"].get("rmse", report["final"].get("rmse_rad"))


def in_truths_form(report, expected):
    """The found effects {name: parameters}, read in the equivalent form the report declares
    (`equivalent_forms`: sets the runs cannot tell apart) where that form is the truth's set, and
    whether it was: judging which of two indistinguishable forms the truth happened to use would score
    a coin. The parameters are then judged in the truth's form."""
    found = {e["effect"]: e["parameters"] for e in report.get("added_effects", [])}
    if set(found) == set(expected):
        return found, False
    for form in report.get("equivalent_forms", []):
        if all(k in found for k in form["found"]):
            other = {k: v for k, v in found.items() if k not in form["found"]}
            other.update(form["equivalent"])
            if set(other) == set(expected):
                return other, True
    return found, False


def score(rig, report):
    """(passed, reasons) of one calibrated rig against its truth."""
    why = []
    found, rig["equivalent_form"] = in_truths_form(report, rig["expected"])
    ratio = final_rmse(report) / rig["floor"]
    if rig["outside"]:
        ok = report.get("unexplained") is True or ratio <= 1.2
        return ok, [] if ok else [f"neither flagged unexplained nor at the floor ({ratio:.2f}×)"]
    if set(found) != set(rig["expected"]):
        why.append(f"effects {sorted(found)} ≠ truth {sorted(rig['expected'])}")
    for effect, params in rig["expected"].items():
        for key, value in params.items():
            got = found.get(effect, {}).get(key)
            if got is None:
                continue
            tol = 0.1 * abs(value) if key != "offset_rad" else 0.02
            if abs(got - value) > tol:
                why.append(f"{effect}.{key} = {got:.4g}, truth {value:.4g}")
    truth = dict(zip(rig["rig"]["temperatures"], zip(rig["k"], rig["c"])))
    for g in report.get("identified", []):
        k, c = truth.get(g["temperature_c"], (None, None))
        if k is None:
            continue
        if abs(g["stiffness"] / k - 1) > 0.1 or abs(g["damping"] / c - 1) > 0.1:
            why.append(f"{g['temperature_c']:g} °C: K {g['stiffness'] / k - 1:+.1%}, C {g['damping'] / c - 1:+.1%}")
    if ratio > 1.2:
        why.append(f"final {ratio:.2f}× the floor")
    if report.get("unexplained"):
        why.append("flagged unexplained")
    return not why, why


def run_rig(rig, out, budget):
    drive = rig.get("kind") == "drive"
    folder = out / (f"drive_{rig['seed']}" if drive else f"rig_{rig['seed']}")
    data, result = folder / "runs", folder / "calibration"
    try:
        generate(drive_truth if drive else truth_model, data, rig["truth_args"])
    except (Exception, SystemExit) as e:  # argparse exits; one rig must not end the campaign
        return {"seed": rig["seed"], "class": rig["class"], "passed": False, "seconds": 0.0,
                "why": [f"the truth model did not make the runs: {type(e).__name__} {e}"], "rig": rig["rig"]}
    truth = json.loads((data / "truth.json").read_text())
    if drive:
        if truth.get("controller"):
            # how far the controller lets friction hold the axis off its reference, in position floors:
            # under one, the positions barely carry the friction (reported beside the rates, not scored)
            rig["rig"]["friction_offset_floors"] = rig["rig"]["coulomb"] / truth["controller"]["kp"] / rig["floor"]
        if truth.get("replay_rms") is not None:
            rig["floor"] = max(rig["floor"], truth["replay_rms"])
        return calibrate_and_score(rig, data, result, budget, score_drive)
    by_temp = {}
    for r in truth["runs"]:
        by_temp[r["temperature_c"]] = (r["stiffness"], r["damping"])
    rig["k"] = [by_temp[t][0] for t in rig["rig"]["temperatures"]]
    rig["c"] = [by_temp[t][1] for t in rig["rig"]["temperatures"]]
    # the replay's floor matters only to a rig above 1.2× the sensor's: replayed then (the replay costs
    # as much as the truth's own run)
    def replay_floor():
        replay = truth_model.replay_rms(data)
        return max(rig["floor"], replay) if replay is not None else rig["floor"]
    return calibrate_and_score(rig, data, result, budget, score, replay_floor)


def lacks_replay(args, truth):
    """Whether a rig's runs predate the truth's own replay (they are made again): a reference-driven
    drive's replay_rms, a device's replay inputs."""
    if "reference" in args:
        return "replay_rms" not in truth
    return "--replay" in args and "replay_rms" not in truth and \
        not all("replay_inputs" in r for r in truth.get("runs", []))


def generate(model, data, args):
    """The rig's runs from its truth model, reused when the folder already holds the runs of these very
    arguments (the truth models are pure Python: the device's RK4 at 1e-4 s is most of a campaign's
    time on a first run)."""
    stamp = data / "truth_args.json"
    # a truth model with a VERSION stamps it beside the arguments: its runs change when it does
    made = args if not hasattr(model, "VERSION") else {"args": args, "version": model.VERSION}
    if stamp.exists() and (data / "truth.json").exists() and json.loads(stamp.read_text()) == made \
            and not lacks_replay(args, json.loads((data / "truth.json").read_text())):
        return
    for old in data.glob("*.csv") if data.exists() else []:
        old.unlink()  # another draw's runs must not join this one's
    model.main(["--out", str(data), *args])
    stamp.write_text(json.dumps(made) + "\n")


def calibrate_and_score(rig, data, result, budget, scorer, replay_floor=None):
    """Calibrates the rig's runs and scores the report; a rig that fails above 1.2× its floor is scored
    again against `replay_floor()` where one is given."""
    started = time.monotonic()
    run = subprocess.run([str(THERMOVIA), "calibrate", str(data), "--out", str(result), "--no-plots",
                          "--search-budget", str(budget)], capture_output=True, text=True)
    seconds = time.monotonic() - started
    if run.returncode != 0:
        return {"seed": rig["seed"], "class": rig["class"], "passed": False, "seconds": seconds,
                "why": [f"calibrate failed: {run.stderr.strip()[-300:]}"], "rig": rig["rig"]}
    report = json.loads((result / "report.json").read_text())
    passed, why = scorer(rig, report)
    if not passed and replay_floor is not None and final_rmse(report) > 1.2 * rig["floor"]:
        rig["floor"] = replay_floor()
        passed, why = scorer(rig, report)
    found = set(in_truths_form(report, rig["expected"])[0]) if rig.get("kind") != "drive" else \
        {e["effect"] for e in report["added_effects"]}
    missed, extra = effect_fates(report, found, rig["expected"]) if not rig["outside"] else ({}, {})
    return {"seed": rig["seed"], "class": rig["class"], "passed": passed, "why": why, "seconds": seconds,
            "ratio": final_rmse(report) / rig["floor"], "added": [e["effect"] for e in report["added_effects"]],
            "equivalent_form": rig.get("equivalent_form", False),
            "expected": sorted(rig["expected"]), "missed": missed, "extra": extra, "rig": rig["rig"]}


# The search's margin on the BIC (stepwise::BIC_MARGIN): a refit that did not lower it by more failed the BIC.
BIC_MARGIN = 10.0


def attempts_of(report):
    """Every refit of the report's chain of evidence, rounds' and combinations' alike."""
    return [a for r in report.get("rounds", []) for a in r.get("attempts", [])] + report.get("combinations", [])


def not_kept(tried):
    """Why refits with an effect were not kept: whether any lowered the BIC by the margin (then the
    rest of the acceptance rule refused it: the structure removed, a bound, a drive's Wald test or
    visibility, named where the report lists them), or none did (the fits never found it worth it)."""
    fell = [a for a in tried if a["bic_after"] < a["bic_before"] - BIC_MARGIN]
    if not fell:
        return "refitted, its BIC never fell"
    failed = sorted({t for a in fell for t in a.get("failed", []) if t != "bic"})
    return "refitted, its BIC fell, not kept" + (f" ({', '.join(failed)})" if failed else "")


def effect_fates(report, found, expected):
    """What the chain of evidence did with each effect the truth has and `found` (the report's
    effects, in the truth's form where it declares one) lacks, and with each it has that the truth
    lacks: {effect: words}, missed and extra."""
    attempts = attempts_of(report)
    ranked = {c["effect"] for r in report.get("rounds", []) for c in r.get("ranking", [])}
    pruned = {p["effect"]: p for p in report.get("pruned_effects", [])}
    missed = {}
    for e in sorted(set(expected) - set(found)):
        tried = [a for a in attempts if e in a.get("effects", [])]
        if e in pruned:
            p = pruned[e]
            how = "below the noise" if p.get("below_noise") else "by the BIC"
            missed[e] = f"pruned {how}" + (f", replaced by {p['replaced_by']}" if p.get("replaced_by") else "")
        elif any(a.get("kept") for a in tried):
            missed[e] = "kept, then swapped out or folded away"
        elif tried:
            missed[e] = not_kept(tried)
        elif e in ranked:
            missed[e] = "ranked, never refitted"
        else:
            missed[e] = "never ranked"
    extra = {}
    for e in sorted(set(found) - set(expected)):
        kept = [a["stage"] for a in attempts if a.get("kept") and e in a.get("effects", [])]
        replaced = [p["effect"] for p in pruned.values() if p.get("replaced_by") == e]
        extra[e] = ("kept at " + ", ".join(dict.fromkeys(kept))) if kept else \
            (f"the lighter form of {', '.join(replaced)}" if replaced else "in by no refit the chain lists")
    return missed, extra


def print_fates(results):
    """How often each fate met a missed or an extra effect over `results` (the rigs' `missed` and
    `extra`): where the loop's misses come from."""
    for key, title in (("missed", "the truth's effects the reports lack"), ("extra", "effects the reports add that the truth lacks")):
        fates = [f.split(" (")[0] for r in results for f in r.get(key, {}).values()]
        if fates:
            counts = sorted(((fates.count(f), f) for f in set(fates)), reverse=True)
            print(f"\n{title} ({len(fates)}): " + "; ".join(f"{f} {n}" for n, f in counts))


def first_small_seeds(drawer, count):
    """The first `count` seeds whose rigs (from `drawer`) hold at most CI_SAMPLES samples (fixed)."""
    seeds, s = [], 1
    while len(seeds) < count:
        if drawer(s)["samples"] <= CI_SAMPLES:
            seeds.append(s)
        s += 1
    return seeds


def ci_seeds():
    """The CI subset's device rigs."""
    return first_small_seeds(draw, CI_RIGS)


def ci_drive_seeds():
    """The CI subset's drive rigs."""
    return first_small_seeds(draw_drive, CI_DRIVE_RIGS)


def print_offset_breakdown(drive_results):
    """The reference-driven rigs' pass rate split where friction's tracking offset under the loop,
    Fc/kp, is under the position floor (the positions barely carry the friction) and over it: what
    the class's rate is made of. Reported, not scored."""
    held = [r for r in drive_results if r.get("rig", {}).get("friction_offset_floors") is not None]
    for name, side in (("under", lambda x: x < 1.0), ("over", lambda x: x >= 1.0)):
        rs = [r for r in held if side(r["rig"]["friction_offset_floors"])]
        if rs:
            print(f"  reference-driven, friction's offset Fc/kp {name} the position floor: "
                  f"{sum(r['passed'] for r in rs)}/{len(rs)} passed")


def bins(x, edges, unit=""):
    """The label of the bin of `edges` x falls in: '≤ e' for the first edge it does not pass, else '> last'."""
    for e in edges:
        if x <= e:
            return f"≤ {e:g}{unit}"
    return f"> {edges[-1]:g}{unit}"


# Every way a campaign splits its rigs (the classes): (name, rig -> label). Device rigs only.
DEVICE_CLASSES = [
    ("effects", lambda r: r["class"]),
    ("excitation", lambda r: r["rig"]["excitation"]),
    ("frequencies per temperature", lambda r: str(len(r["rig"]["frequencies_hz"]))),
    ("rate", lambda r: bins(r["rig"]["rate_hz"], (500, 2000), " Hz")),
    ("run length", lambda r: bins(r["rig"]["duration_s"], (10, 30), " s")),
    ("timestamp jitter", lambda r: "with" if r["rig"]["jitter"] > 0 else "none"),
    ("gaps", lambda r: "with" if r["rig"]["dropout_s"] > 0 else "none"),
    ("link inertia", lambda r: bins(r["rig"]["inertia"], (0.01, 0.05), " kg·m²")),
    ("natural frequency over the excitation's", lambda r: bins(
        r["rig"]["natural_frequency_hz"] / max(r["rig"]["frequencies_hz"]), (5, 15))),
    ("temperatures", lambda r: str(len(r["rig"]["temperatures"]))),
    ("temperature", lambda r: "drifting" if r["rig"].get("drift_k") else "steady"),
    ("encoder q/√12 over the noise", lambda r: bins(
        2 * math.pi / r["rig"]["counts_per_turn"] / math.sqrt(12) / r["rig"]["noise"], (0.3, 1, 3, 10))),
]
DRIVE_CLASSES = [
    ("kind", lambda r: r["class"]),
    ("rate", lambda r: bins(r["rig"]["rate_hz"], (500, 2000), " Hz")),
    ("timestamp jitter", lambda r: "with" if r["rig"]["jitter"] > 0 else "none"),
    ("gaps", lambda r: "with" if r["rig"].get("dropout_s", 0) > 0 else "none"),
    ("scale (kg·m² or kg)", lambda r: bins(r["rig"]["inertia"], (1e-3, 1))),
]


def bin_order(item):
    """Sort key of a class label: the `bins` labels by their edge (every '≤ e' before the '> last'),
    other labels as text."""
    label = item[0]
    try:
        edge = float(label.split()[1])
    except (IndexError, ValueError):
        return (1, 0.0, label)
    return (0, edge + (1e-9 * abs(edge) if label.startswith(">") else 0.0), label)


def grouped(results, label):
    """`results` split by `label` (a rig it cannot label goes under 'unknown'), as (label, rigs) in
    the bins' order."""
    groups = {}
    for r in results:
        try:
            key = label(r)
        except (KeyError, TypeError, ZeroDivisionError):
            key = "unknown"
        groups.setdefault(key, []).append(r)
    return sorted(groups.items(), key=bin_order)


def passed_of(rigs):
    """How many of `rigs` passed, of how many."""
    return f"{sum(r['passed'] for r in rigs)}/{len(rigs)}"


def median_time(rigs):
    """The median calibration wall time of `rigs`, with their number: which rigs a campaign's median
    waits on (on fresh seeds 1371–1410, those with a drifting thermocouple, docs/performance.md)."""
    return f"{statistics.median(r['seconds'] for r in rigs):.1f} s ({len(rigs)})"


def print_classes(results, title, classes, summary=passed_of):
    """`summary` (the pass rate) of `results` split every way `classes` splits them."""
    if not results:
        return
    print(f"\n{title}")
    for name, label in classes:
        print(f"  {name}: " + ", ".join(f"{k} {summary(rs)}" for k, rs in grouped(results, label)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("out/campaign"), help="folder for the rigs and campaign.json")
    ap.add_argument("--rigs", type=int, default=300, help="number of rigs (seeds first-seed …)")
    ap.add_argument("--drive-rigs", type=int, default=100, help="number of drive rigs (seeds first-seed …)")
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--only", choices=["device", "drive"], help="run one kind of rig")
    ap.add_argument("--ci", action="store_true",
                    help=f"the CI subset: {CI_RIGS} device and {CI_DRIVE_RIGS} drive rigs, fixed seeds of at most {CI_SAMPLES} samples")
    ap.add_argument("--search-budget", type=float, default=120.0, help="thermovia calibrate --search-budget, s")
    ap.add_argument("--jobs", type=int, default=1,
                    help="rigs at once (each calibration already uses every core; 2 overlaps one rig's Python "
                         "truth model with another's calibration, and each rig's wall time is then a shared "
                         "machine's: 1 measures a rig's own)")
    ap.add_argument("--require", nargs=2, action="append", default=[], metavar=("KIND", "PERCENT"),
                    help="exit 1 when the pass rate of KIND (device, drive, outside) falls below PERCENT: CI holds "
                         "the subset to the rates measured when it was last improved (a ratchet, never a target)")
    a = ap.parse_args(argv)
    device = ci_seeds() if a.ci else list(range(a.first_seed, a.first_seed + a.rigs))
    drives = ci_drive_seeds() if a.ci else list(range(a.first_seed, a.first_seed + a.drive_rigs))
    rigs = ([] if a.only == "drive" else [draw(s) for s in device]) + \
        ([] if a.only == "device" else [draw_drive(s) for s in drives])
    seeds = [r["seed"] for r in rigs]
    a.out.mkdir(parents=True, exist_ok=True)
    results = []
    with concurrent.futures.ProcessPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        futures = [pool.submit(run_rig, rig, a.out, a.search_budget) for rig in rigs]
        for i, future in enumerate(futures):
            r = future.result()
            results.append(r)
            mark = ("pass" if r["passed"] else "FAIL") + (" (in the truth's equivalent form)" if r.get("equivalent_form") else "")
            print(f"[{i + 1}/{len(seeds)}] seed {r['seed']} ({r['class']}): {mark} in {r['seconds']:.1f} s"
                  + ("" if r["passed"] else f": {'; '.join(r['why'])}"), flush=True)
            (a.out / "campaign.json").write_text(json.dumps({"seeds": seeds, "results": results}, indent=1) + "\n")
    classes = sorted({r["class"] for r in results})
    print("\nclass                      rigs  passed  rate")
    for c in classes:
        rs = [r for r in results if r["class"] == c]
        n = sum(r["passed"] for r in rs)
        print(f"{c:<26} {len(rs):>4}  {n:>6}  {100 * n / len(rs):5.1f} %")
    inside = [r for r in results if r["class"] != "outside library" and not r["class"].startswith("drive")]
    n = sum(r["passed"] for r in results)
    print(f"{'all':<26} {len(results):>4}  {n:>6}  {100 * n / len(results):5.1f} %")
    if inside:
        print(f"device rigs inside the library: {100 * sum(r['passed'] for r in inside) / len(inside):.1f} %")
        equivalent = sum(r["passed"] and r.get("equivalent_form", False) for r in inside)
        if equivalent:
            print(f"  of which {equivalent} passed in the equivalent form of the truth's effects (equivalent_forms)")
    print_fates(inside)
    print_classes(inside, "device rigs inside the library, per class (passed/rigs):", DEVICE_CLASSES)
    drive_results = [r for r in results if r["class"].startswith("drive")]
    print_classes(drive_results, "drive rigs, per class (passed/rigs):", DRIVE_CLASSES)
    if drive_results:
        print(f"drive rigs: {100 * sum(r['passed'] for r in drive_results) / len(drive_results):.1f} %")
        print_offset_breakdown(drive_results)
        print_fates(drive_results)
    kinds = {
        "device": inside,
        "drive": [r for r in results if r["class"].startswith("drive")],
        "outside": [r for r in results if r["class"] == "outside library"],
    }
    short = []
    for kind, percent in a.require:
        rs = kinds.get(kind)
        if rs is None:
            ap.error(f"--require {kind}: KIND is one of {', '.join(kinds)}")
        rate = 100 * sum(r["passed"] for r in rs) / max(1, len(rs))
        if rate < float(percent):
            short.append(f"{kind} rigs pass {rate:.1f} %, below the {float(percent):g} % required")
    secs = [r["seconds"] for r in results]
    print(f"calibration wall time ({a.jobs} rig{'s' if a.jobs > 1 else ''} at a time): "
          f"median {statistics.median(secs):.1f} s, max {max(secs):.1f} s")
    print_classes([r for r in results if not r["class"].startswith("drive")],
                  "device rigs' calibration wall time, median per class (rigs):", DEVICE_CLASSES, median_time)
    for line in short:
        print(f"campaign: {line}", file=sys.stderr)
    if short:
        sys.exit(1)
    return results


if __name__ == "__main__":
    main()
