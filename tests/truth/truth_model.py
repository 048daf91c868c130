"""An independent truth model of a rig like ThermoVIA's, written apart from the FMU and its Rust
code: the motor angle is prescribed (the measured angle drives the model), the output link of
inertia J hangs on a transmission of stiffness K and damping C (per temperature, chosen directly,
not from the FMU's material table), and effects act on the link as the Modelica Standard Library
defines them:

- backlash: the clipped spring–damper (Modelica's ElastoBacklash without its cap |τ_d| ≤ |τ_c|). With the relative angle φ = θm − θl and half-play b = width/2, the
  spring acts on the part of φ beyond ±b; the damper acts only while in contact and never pulls:
  τ = K(φ − b) + C φ' for φ > b, clipped at ≥ 0 (and symmetric for φ < −b), τ = 0 inside the play.
  `elasto_backlash=WIDTH` instead: Modelica's Rotational.Components.ElastoBacklash itself, τ_c = K(φ − b),
  τ_d = C φ', τ = τ_c + min(τ_c, τ_d) for φ > b unless τ_c + τ_d ≤ 0 (then 0), τ_c + max(τ_c, τ_d) for φ < −b
  unless τ_c + τ_d ≥ 0.
- Coulomb friction: BearingFriction with a smooth sign, τ_f = Fc tanh(θl'/v_s) (v_s small);
- Stribeck friction: τ_f = (Fc + Fs exp(−(θl'/v_st)²)) tanh(θl'/v_s);
- asymmetric friction (no Modelica element: defined here): τ_f = Fc± tanh(θl'/v_s) + Bv± θl', with Fc+, Bv+
  for θl' > 0 and Fc−, Bv− for θl' < 0 (continuous at rest: both terms vanish there);
- gravity: τ_g = −mgl sin(θl − offset);
- link damping to ground: τ = −B θl'; constant load: τ = τ_0;
- hardening spring (outside the calibration's effect library): the spring part of the transmission is
  K φ (1 + α φ²) (secant stiffness K(1 + α φ²)), on the excess beyond the play when there is backlash;
- a stiffness that depends on the link's angle (outside the library too): K(θl) = K (1 + β θl²).

A drifting temperature (`--drift`): each run's housing thermocouple heats through the run (a heater's
first-order approach, logged as a `temperature_c` column), the PCL follows it, and K and C follow the
paper's device's shape in temperature (Table 2, `transmission_shape`), scaled to the run's K and C at its
nominal temperature (the `# temperature_c=` metadata, the drift's midpoint). `--effect thermal_lag=TAU`:
the PCL follows the thermocouple through a first-order lag (starting level with it).

Excitation of the motor angle (`--excitation`): `sine` (one run per temperature and frequency, the
default), `multisine` (a few sines 0.2–3 Hz, random phases, amplitudes ∝ 1/√f scaled to the sine's rms),
`steps` (random levels within ±amplitude, random dwell 0.8–2.5 s, each step smoothed by tanh over
0.05 s). The motor angle and its speed are analytic. `--initial-speed V`: the link starts at the motor's
angle with speed V and the motor starts mid-swing (sine phase 45°, the first step centred on t = 0;
a multisine's random phases already start it mid-swing); otherwise the link starts at rest at the
motor's initial angle.

Integration: classical RK4 at a fine fixed step (default 1e-4 s), split where a large friction on a light
link makes the friction's smoothed sign stiff (`rk4_advance`), with the motor angle and speed given
analytically. Measurements: Gaussian noise, then encoder quantisation, then (optionally)
timestamp jitter. Files follow docs/interfaces.md (one CSV per run, `# key=value` metadata).

  .venv/bin/python tests/truth/truth_model.py --out out/truth --effect backlash=0.02 --stiffness-scale 5
  .venv/bin/python tests/truth/truth_model.py --out out/truth --excitation multisine --effect stribeck=0.03,0.05
"""
import argparse
import json
import math
from pathlib import Path

import numpy as np

# Stamped beside a campaign's cached runs (tests/truth/campaign.py): 2 splits the steps of a stiff friction.
VERSION = 2

ENCODER_QUANTUM = 2 * math.pi / 10000  # 2500 lines × 4 edges per revolution


def link_torque(phi, dphi, v, p):
    """Torque on the link from the transmission and the effects (v = link speed)."""
    k, c = p["stiffness"], p["damping"]
    # a stiffness that depends on the link's angle (a cam-like transmission; outside the library)
    k *= 1.0 + p.get("angle_stiffness_beta", 0.0) * p.get("theta_l", 0.0) ** 2
    b = 0.5 * p.get("backlash", 0.0)
    alpha = p.get("hardening_alpha", 0.0)
    elasto_b = 0.5 * p.get("elasto_backlash", 0.0)
    if elasto_b > 0.0:
        if phi > elasto_b:
            x = phi - elasto_b
            tc, td = k * x * (1.0 + alpha * x * x), c * dphi
            tau = 0.0 if tc + td <= 0.0 else tc + min(tc, td)
        elif phi < -elasto_b:
            x = phi + elasto_b
            tc, td = k * x * (1.0 + alpha * x * x), c * dphi
            tau = 0.0 if tc + td >= 0.0 else tc + max(tc, td)
        else:
            tau = 0.0
    elif b > 0.0:
        if phi > b:
            x = phi - b
            tau = max(k * x * (1.0 + alpha * x * x) + c * dphi, 0.0)
        elif phi < -b:
            x = phi + b
            tau = min(k * x * (1.0 + alpha * x * x) + c * dphi, 0.0)
        else:
            tau = 0.0
    else:
        tau = k * phi * (1.0 + alpha * phi * phi) + c * dphi
    vs = p.get("friction_smoothing", 1e-3)
    fc = p.get("coulomb_friction", 0.0)
    fs = p.get("stribeck_friction", 0.0)
    if fc > 0.0 or fs > 0.0:
        vst = p.get("stribeck_velocity", 0.05)
        tau -= (fc + fs * math.exp(-(v / vst) ** 2)) * math.tanh(v / vs)
    if "asym_coulomb_positive" in p:
        if v > 0.0:
            tau -= p["asym_coulomb_positive"] * math.tanh(v / vs) + p["asym_viscous_positive"] * v
        else:
            tau -= p["asym_coulomb_negative"] * math.tanh(v / vs) + p["asym_viscous_negative"] * v
    if p.get("gravity_mgl", 0.0) > 0.0:
        tau -= p["gravity_mgl"] * math.sin(p["theta_l"] - p.get("gravity_offset", 0.0))
    tau -= p.get("link_damping", 0.0) * v
    tau += p.get("constant_load", 0.0)
    return tau


# The smoothed friction F tanh(θl'/v_s) has slope F/v_s at zero speed: over the link's inertia a rate
# λ = F/(v_s J) of 1e5–1e6 /s on a light link with a large friction. Classical RK4 is stable only for
# h·λ ≤ 2.79 on the real axis; beyond, a held link's speed chatters about zero instead of creeping at
# v_s atanh(τ/F), and the runs carry an artefact of the integrator that no exact model reproduces (campaign
# rig 173, Coulomb friction 1.13 N·m on 0.0089 kg·m², h·λ = 12.7 at 1e-4 s: the FMU at the truth's values
# 11× the noise floor; with the step below, 1.02×). Where the speed is in the sign's zone, or can reach it
# within a step, each step is split so that h·λ ≤ STIFF_STEP (RK4 there damps the fast mode as e^{−hλ}
# does to 2 %).
STIFF_STEP = 1.0
SIGN_ZONE = 20.0  # |θl'|/v_s beyond which tanh rounds to ±1 (its slope below 1e-16 of the peak)


# A run's housing thermocouple may drift (`--drift`): the PCL follows it (no lag) and the transmission's
# K and C follow the PCL as the paper's device does: the springs, 12 × 1.16 N/mm at r_s = 22.2 mm (Table 1),
# beside κ r_p² E'(T) (κ = 0.064 m, r_p = 20.75 mm, docs/physics.md §3), and C ∝ E''(T), with E' and E''
# from Table 2's experimental columns, the small entries read as MPa (physics.md §4, its repaired reading),
# log E interpolated against T and held beyond 22–60 °C. Written from the paper and the physics notes,
# not from the FMU's code. The rig's own K and C at its nominal temperature scale that shape.
TABLE_C = (22.0, 40.0, 50.0, 60.0)
TABLE_E1_KPA = (985.34, 920.0, 400.0, 180.0)
TABLE_E2_KPA = (834.45, 1820.0, 1230.0, 120.0)
SPRING_BANK = 12 * 1.16e3 * 0.0222 ** 2  # N·m/rad
PCL_GEOMETRY = 0.064 * 0.02075 ** 2  # κ r_p², m³


def table_modulus(column_kpa, temp_c):
    """A Table 2 column at temp_c, Pa: log E piecewise linear in T between the rows, held beyond."""
    if temp_c <= TABLE_C[0]:
        return column_kpa[0] * 1e3
    for i in range(1, len(TABLE_C)):
        if temp_c <= TABLE_C[i]:
            w = (temp_c - TABLE_C[i - 1]) / (TABLE_C[i] - TABLE_C[i - 1])
            return column_kpa[i - 1] * 1e3 * (column_kpa[i] / column_kpa[i - 1]) ** w
    return column_kpa[-1] * 1e3


def transmission_shape(temp_c):
    """(K, C) of the paper's device at temp_c up to one factor each: springs + κ r_p² E', and E''."""
    return SPRING_BANK + PCL_GEOMETRY * table_modulus(TABLE_E1_KPA, temp_c), table_modulus(TABLE_E2_KPA, temp_c)


def heating(temp_c, kelvin, duration, time_constant):
    """A run's drift (`housing_temperature`): temp_c − kelvin/2 at its start to temp_c + kelvin/2 at its end."""
    return {"from_c": temp_c - kelvin / 2, "to_c": temp_c + kelvin / 2, "duration_s": duration,
            "time_constant_s": time_constant}


def housing_temperature(drift, t):
    """The thermocouple at t, °C, of a run whose `drift` is {"from_c", "to_c", "duration_s", "time_constant_s"}:
    a heater's first-order approach, from_c at 0 and to_c at the run's end."""
    tau, span = drift["time_constant_s"], drift["duration_s"]
    return drift["from_c"] + (drift["to_c"] - drift["from_c"]) * (1.0 - math.exp(-t / tau)) / (1.0 - math.exp(-span / tau))


def pcl_temperature(drift, t, lag):
    """The PCL at t, °C: the thermocouple (`housing_temperature`) through a first-order lag of time
    constant `lag` s (0: none), starting level with it. The housing is A − B e^{−t/τh}, so the PCL is
    A − B' e^{−t/τh} + (B' − B) e^{−t/τ} with B' = B τh/(τh − τ) (τ = τh: A − B (1 + t/τ) e^{−t/τ})."""
    if lag <= 0.0:
        return housing_temperature(drift, t)
    tau_h, span = drift["time_constant_s"], drift["duration_s"]
    b = (drift["to_c"] - drift["from_c"]) / (1.0 - math.exp(-span / tau_h))
    a = drift["from_c"] + b
    if abs(tau_h - lag) < 1e-9 * tau_h:
        return a - b * (1.0 + t / lag) * math.exp(-t / lag)
    b_lag = b * tau_h / (tau_h - lag)
    return a - b_lag * math.exp(-t / tau_h) + (b_lag - b) * math.exp(-t / lag)


def transmission_schedule(k, c, temp_c, drift, lag=0.0):
    """t -> (K, C) of a run whose K and C at its nominal temperature temp_c are k and c, its
    thermocouple drifting as `drift` says and the PCL lagging it by `lag` s; None for a steady run."""
    if drift is None:
        return None
    k0, c0 = transmission_shape(temp_c)

    def at(t):
        ks, cs = transmission_shape(pcl_temperature(drift, t, lag))
        return k * ks / k0, c * cs / c0
    return at


def friction_rate(p):
    """λ = (F_c + F_s + the larger asymmetric level)/(v_s J), 1/s: how fast the friction's smoothed sign
    relaxes the link's speed near zero (0 without friction)."""
    level = p.get("coulomb_friction", 0.0) + p.get("stribeck_friction", 0.0)
    level += max(p.get("asym_coulomb_positive", 0.0), p.get("asym_coulomb_negative", 0.0))
    return level / (p.get("friction_smoothing", 1e-3) * p["inertia"])


def sign_zone(p):
    """The link speed below which the friction's smoothed sign is not yet ±1, rad/s."""
    return SIGN_ZONE * p.get("friction_smoothing", 1e-3)


def rk4_advance(acc, t, th, v, h, rate, zone):
    """(θ, θ') after h from (θ, θ') at t: one RK4 step, or where the friction is stiff at this step
    (h·λ > STIFF_STEP, λ = `rate`, `friction_rate`) and the speed is within the sign's zone (`zone`,
    `sign_zone`) or can reach it in h (at twice the acceleration now), n = ⌈h·λ/STIFF_STEP⌉ steps of h/n."""
    a1 = acc(t, th, v)
    n = math.ceil(h * rate / STIFF_STEP - 1e-9) if rate > 0.0 else 1
    if n <= 1 or abs(v) > zone + 2.0 * abs(a1) * h:
        return rk4_step(acc, t, th, v, h, a1)
    sub = h / n
    for k in range(n):
        th, v = rk4_step(acc, t + k * sub, th, v, sub, a1 if k == 0 else None)
    return th, v


def rk4_step(acc, t, th, v, h, a1=None):
    """One classical RK4 step of θ'' = acc(t, θ, θ') from (θ, θ') at t: the new (θ, θ'); `a1`, where
    given, is acc(t, θ, θ') already evaluated."""
    if a1 is None:
        a1 = acc(t, th, v)
    a2 = acc(t + h / 2, th + h / 2 * v, v + h / 2 * a1)
    a3 = acc(t + h / 2, th + h / 2 * (v + h / 2 * a1), v + h / 2 * a2)
    a4 = acc(t + h, th + h * (v + h / 2 * a2), v + h * a3)
    return th + h / 6 * (v + 2 * (v + h / 2 * a1) + 2 * (v + h / 2 * a2) + (v + h * a3)), v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)


def simulate(p, t_end, dt, motor, schedule=None):
    """RK4 of θl, θl' with the motor angle motor(t) -> (angle, speed) and, where given, the transmission's
    (K, C) schedule(t) (`transmission_schedule`). Returns the fine time grid and the link angle and speed
    on it. Plain floats: numpy per step would cost more than the arithmetic."""
    n = int(round(t_end / dt))
    th, v = p.get("initial_link_angle", 0.0), p.get("initial_link_speed", 0.0)
    out, speed = np.empty(n + 1), np.empty(n + 1)
    out[0], speed[0] = th, v
    j = p["inertia"]
    rate, zone = friction_rate(p), sign_zone(p)

    def acc(t, th, v):
        m, dm = motor(t)
        p["theta_l"] = th
        if schedule is not None:
            p["stiffness"], p["damping"] = schedule(t)
        return link_torque(m - th, dm - v, v, p) / j

    for i in range(n):
        th, v = rk4_advance(acc, i * dt, th, v, dt, rate, zone)
        out[i + 1], speed[i + 1] = th, v
    return np.arange(n + 1) * dt, out, speed


def replay(p, t_log, m_log, vm_true, starts, dt, schedule=None):
    """The truth's own link driven by the logged motor angle, as a calibration's model must be: the
    motor angle between two logged samples is the straight line through them, on the logged
    (jittered) times, in RK4 substeps of at most dt. The motor's speed is the truth's own
    (`vm_true` at each sample, interpolated likewise): a calibration smooths the logged angle for
    its speed, and the raw line's slope, jumping by a count per sample, would drive the damper with
    spikes the smoothing removes (a never-pulling backlash contact rectifies them into a bias). The
    link starts each stretch from the truth's own state (`starts`: sample index -> (angle, speed),
    the first sample and the first after each dropout), which no calibration knows better. So the
    replay errs only by what the log cannot tell: the motor encoder's offset (up to half a count
    while the motor holds), its noise and the timestamps' jitter. Returns the link angle at every
    logged sample."""
    out = np.empty(len(t_log))
    j = p["inertia"]
    rate, zone = friction_rate(p), sign_zone(p)
    th = v = 0.0
    for i in range(len(t_log)):
        if i in starts:
            th, v = starts[i]
        out[i] = th
        if i + 1 == len(t_log):
            break
        t0, span = t_log[i], t_log[i + 1] - t_log[i]
        slope = (m_log[i + 1] - m_log[i]) / span
        dv = (vm_true[i + 1] - vm_true[i]) / span
        steps = max(1, math.ceil(span / dt - 1e-9))
        h = span / steps

        def acc(t, th, v):
            p["theta_l"] = th
            if schedule is not None:
                p["stiffness"], p["damping"] = schedule(t)
            return link_torque(m_log[i] + slope * (t - t0) - th, vm_true[i] + dv * (t - t0) - v, v, p) / j

        for s in range(steps):
            th, v = rk4_advance(acc, t0 + s * h, th, v, h, rate, zone)
    return out


def replay_rms(folder):
    """The rms of the logged link against the truth's replay (`replay`) over every run of a folder made
    with --replay, computed once and kept in its truth.json as `replay_rms`; None without --replay."""
    folder = Path(folder)
    truth = json.loads((folder / "truth.json").read_text())
    if "replay_rms" in truth:
        return truth["replay_rms"]
    if not truth["runs"] or any("replay_inputs" not in r for r in truth["runs"]):
        return None
    sse, samples = 0.0, 0
    for run in truth["runs"]:
        d = np.load(folder / run["replay_inputs"])
        p = {"stiffness": run["stiffness"], "damping": run["damping"], "inertia": truth["inertia"],
             **parse_effects(truth["effect_options"])}
        starts = {int(i): (float(a), float(v)) for i, a, v in zip(d["starts"], d["start_angles"], d["start_speeds"])}
        schedule = transmission_schedule(run["stiffness"], run["damping"], run["temperature_c"], run.get("drift"),
                                         p.get("thermal_lag", 0.0))
        replayed = replay(p, d["time"], d["motor"], d["motor_speed"], starts, truth["dt"], schedule)
        sse += float(np.sum((d["link"] - replayed) ** 2))
        samples += len(replayed)
    truth["replay_rms"] = math.sqrt(sse / samples)
    (folder / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return truth["replay_rms"]


def write_run(path, meta, columns):
    names = list(columns)
    with open(path, "w", encoding="utf-8") as fh:
        for k, v in meta.items():
            fh.write(f"# {k}={v}\n")
        fh.write(",".join(names) + "\n")
        for row in zip(*(columns[n] for n in names)):
            fh.write(",".join(repr(float(x)) for x in row) + "\n")


# One-value effect options: the key of the parameter dict they set.
FLAT_EFFECTS = ("thermal_lag", "backlash", "elasto_backlash", "coulomb_friction", "stribeck_friction", "stribeck_velocity", "gravity_mgl",
                "gravity_offset", "link_damping", "constant_load", "friction_smoothing")
# Several-value effect options: the keys they set, in order.
COMPOUND_EFFECTS = {
    "stribeck": ("stribeck_friction", "stribeck_velocity"),
    "asymmetric_friction": ("asym_coulomb_positive", "asym_coulomb_negative", "asym_viscous_positive",
                            "asym_viscous_negative"),
    "hardening": ("hardening_alpha",),
    "angle_stiffness": ("angle_stiffness_beta",),
}
MULTISINE_FREQUENCIES = (0.2, 0.4, 0.8, 1.6, 3.0)  # multiples of 0.2 Hz: 5 s hold whole cycles of each
STEP_SMOOTHING = 0.05  # s, tanh time scale of each step
STEP_DWELL = (0.8, 2.5)  # s


def parse_effects(items):
    """`NAME=V[,V...]` options → the flat parameter dict link_torque reads. Raises ValueError."""
    flat = {}
    for e in items:
        name, _, value = e.partition("=")
        try:
            values = [float(x) for x in value.split(",")]
        except ValueError:
            raise ValueError(f"--effect {e}: values must be numbers") from None
        if name in FLAT_EFFECTS and len(values) == 1:
            flat[name] = values[0]
        elif name in COMPOUND_EFFECTS and len(values) == len(COMPOUND_EFFECTS[name]):
            flat.update(zip(COMPOUND_EFFECTS[name], values))
        else:
            known = [f"{n}=V" for n in FLAT_EFFECTS] + [f"{n}=" + ",".join("V" * len(k)) for n, k in COMPOUND_EFFECTS.items()]
            raise ValueError(f"--effect {e}: unknown or wrong number of values (known: {', '.join(known)})")
    return flat


def effects_json(flat):
    """The flat parameters → effects named as in docs/interfaces.md, with their parameters."""
    out = {}
    if flat.get("coulomb_friction", 0.0) > 0.0:
        out["coulomb_friction"] = {"torque_nm": flat["coulomb_friction"]}
    if flat.get("stribeck_friction", 0.0) > 0.0:
        out["stribeck_friction"] = {"torque_nm": flat["stribeck_friction"], "velocity": flat.get("stribeck_velocity", 0.05)}
    if "asym_coulomb_positive" in flat:
        out["asymmetric_friction"] = {k: flat["asym_" + k] for k in
                                      ("coulomb_positive", "coulomb_negative", "viscous_positive", "viscous_negative")}
    if flat.get("constant_load", 0.0) != 0.0:
        out["constant_load"] = {"torque_nm": flat["constant_load"]}
    if flat.get("backlash", 0.0) > 0.0:
        out["backlash"] = {"width_rad": flat["backlash"]}
    if flat.get("elasto_backlash", 0.0) > 0.0:
        out["backlash"] = {"width_rad": flat["elasto_backlash"], "law": "elasto_backlash"}
    if flat.get("gravity_mgl", 0.0) > 0.0:
        out["gravity"] = {"mgl_nm": flat["gravity_mgl"], "offset_rad": flat.get("gravity_offset", 0.0)}
    if flat.get("link_damping", 0.0) > 0.0:
        out["link_damping"] = {"damping_nms": flat["link_damping"]}
    if flat.get("thermal_lag", 0.0) > 0.0:
        out["thermal_lag"] = {"time_constant_s": flat["thermal_lag"]}
    if flat.get("hardening_alpha", 0.0) != 0.0:
        out["hardening_spring"] = {"alpha_per_rad2": flat["hardening_alpha"], "out_of_library": True}
    if flat.get("angle_stiffness_beta", 0.0) != 0.0:
        out["angle_dependent_stiffness"] = {"beta_per_rad2": flat["angle_stiffness_beta"], "out_of_library": True}
    return out


def excitation(kind, amplitude, frequency, duration, rng, moving=False):
    """The motor angle: (motor(t) -> (angle, speed), description for truth.json)."""
    if kind == "sine":
        w, ph = 2 * math.pi * frequency, (math.pi / 4 if moving else 0.0)
        return (lambda t: (amplitude * math.sin(w * t + ph), amplitude * w * math.cos(w * t + ph))), \
            {"kind": "sine", "frequency_hz": frequency, "amplitude_rad": amplitude, "phase_rad": ph}
    if kind == "multisine":
        fs = np.array(MULTISINE_FREQUENCIES)
        amps = fs ** -0.5
        amps *= amplitude / math.sqrt(np.sum(amps ** 2))  # rms of the sum = the sine's, amplitude/√2
        phases = rng.uniform(0.0, 2 * math.pi, fs.size)
        parts = [(float(a), 2 * math.pi * float(f), float(p)) for a, f, p in zip(amps, fs, phases)]

        def motor(t):
            x = v = 0.0
            for a, w, p in parts:
                x += a * math.sin(w * t + p)
                v += a * w * math.cos(w * t + p)
            return x, v
        return motor, {"kind": "multisine", "frequencies_hz": fs.tolist(), "amplitudes_rad": amps.tolist(),
                       "phases_rad": phases.tolist()}
    if kind == "steps":
        times, levels, t, level = [], [], (0.0 if moving else rng.uniform(0.3, 0.8)), 0.0
        while t < duration:
            new = float(rng.uniform(-amplitude, amplitude))
            times.append(t)
            levels.append(new - level)
            level = new
            t += rng.uniform(*STEP_DWELL)
        tau = STEP_SMOOTHING
        steps = list(zip(times, levels))

        def motor(t):
            x = v = 0.0
            for ti, d in steps:
                z = (t - ti) / tau
                if z > 20.0:
                    x += d
                elif z > -20.0:
                    th = math.tanh(z)
                    x += 0.5 * d * (1.0 + th)
                    v += 0.5 * d * (1.0 - th * th) / tau
            return x, v
        return motor, {"kind": "steps", "times_s": times, "increments_rad": levels, "smoothing_s": tau}
    raise ValueError(f"unknown excitation {kind!r}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, type=Path, help="folder for the run files and truth.json")
    ap.add_argument("--temperatures", default="22,40,50,60", help="run temperatures, °C (comma-separated)")
    ap.add_argument("--frequencies", default="0.5,1",
                    help="motor frequencies, Hz (comma-separated); for multisine and steps only their count "
                         "matters: that many runs per temperature, each with its own random phases or steps")
    ap.add_argument("--excitation", choices=("sine", "multisine", "steps"), default="sine",
                    help="motor angle: one sine per run, a multisine 0.2–3 Hz, or smoothed random steps")
    ap.add_argument("--stiffness", default="34,20,12,5",
                    help="transmission stiffness per temperature, N·m/rad (comma-separated, one per temperature)")
    ap.add_argument("--damping", default="0.4,0.3,0.2,0.1", help="transmission damping per temperature, N·m·s/rad")
    ap.add_argument("--stiffness-scale", type=float, default=1.0, help="factor on every stiffness")
    ap.add_argument("--inertia", type=float, default=0.018, help="link inertia, kg·m²")
    ap.add_argument("--declare-inertia", action="store_true", help="write link_inertia_kgm2 into the files")
    ap.add_argument("--amplitude", type=float, default=0.3, help="motor amplitude, rad")
    ap.add_argument("--duration", type=float, default=20.0, help="run length, s")
    ap.add_argument("--initial-speed", type=float, default=None, metavar="RAD_PER_S",
                    help="the run starts moving: the link's initial speed, the motor mid-swing")
    ap.add_argument("--rate", type=float, default=1000.0, help="sampling rate, Hz")
    ap.add_argument("--dt", type=float, default=1e-4, help="integration step, s (a divisor of the sample period)")
    ap.add_argument("--noise", type=float, default=1e-4, help="sensor noise std before quantisation, rad")
    ap.add_argument("--quantum", type=float, default=ENCODER_QUANTUM, help="encoder step, rad (0: none)")
    ap.add_argument("--jitter", type=float, default=0.0,
                    help="timestamp jitter: each logged time is off by up to ± this fraction of a sample period "
                         "(uniform; the samples themselves stay on the uniform grid); below 0.5")
    ap.add_argument("--dropout", type=float, default=0.0, metavar="SECONDS",
                    help="a logger's dropout: each run loses the samples of one stretch this long, placed at random "
                         "in its middle half (the time base keeps its gap)")
    ap.add_argument("--drift", type=float, default=0.0, metavar="KELVIN",
                    help="each run's thermocouple heats by this much, from its temperature − KELVIN/2 to + KELVIN/2, "
                         "logged as a temperature_c column; K and C follow the paper's Table 2 shape (heating only)")
    ap.add_argument("--drift-time-constant", type=float, default=None, metavar="SECONDS",
                    help="the heating's first-order time constant (default: the run's duration)")
    ap.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE[,VALUE...]",
                    help="thermal_lag=TAU (the PCL behind the thermocouple, first order; with --drift), "
                         "backlash=WIDTH, elasto_backlash=WIDTH (Modelica's ElastoBacklash), coulomb_friction=FC, stribeck_friction=FS, stribeck_velocity=VST, "
                         "stribeck=FS,VST, asymmetric_friction=FCP,FCN,BVP,BVN, gravity_mgl=MGL, gravity_offset=RAD, "
                         "link_damping=B, constant_load=TAU, hardening=ALPHA (spring K φ(1 + α φ²), outside the "
                         "calibration's library), friction_smoothing=VS (repeatable)")
    ap.add_argument("--replay", action="store_true",
                    help="keep what the truth's replay driven by the logged motor angle needs (`replay`), one "
                         "RUN.replay.npz beside each run; `replay_rms(folder)` then gives the measured link's rms "
                         "against it: the floor a calibration driven by that log can reach (quantisation and "
                         "noise of the motor's encoder, jitter)")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args(argv)
    temps = [float(x) for x in a.temperatures.split(",")]
    freqs = [float(x) for x in a.frequencies.split(",")]
    ks = [float(x) * a.stiffness_scale for x in a.stiffness.split(",")]
    cs = [float(x) for x in a.damping.split(",")]
    if not (len(ks) == len(cs) == len(temps)):
        ap.error("--stiffness and --damping need one value per temperature")
    if a.drift < 0.0:
        ap.error("--drift must be ≥ 0: the truth heats only (cooling a melted PCL leaves Table 2's branch)")
    if a.drift_time_constant is not None and not a.drift_time_constant > 0.0:
        ap.error("--drift-time-constant must be > 0")
    if not 0.0 <= a.jitter < 0.5:
        ap.error("--jitter must be in [0, 0.5): the logged times must stay increasing")
    try:
        effects = parse_effects(a.effect)
    except ValueError as err:
        ap.error(str(err))
    if "thermal_lag" in effects and not a.drift > 0.0:
        ap.error("--effect thermal_lag needs --drift: behind a steady thermocouple a lag shows nothing")
    rng = np.random.default_rng(a.seed)
    a.out.mkdir(parents=True, exist_ok=True)
    stride = int(round(1.0 / (a.rate * a.dt)))
    truth = {"inertia": a.inertia, "effects": effects_json(effects), "effect_options": a.effect, "noise": a.noise,
             "quantum": a.quantum, "jitter": a.jitter, "rate_hz": a.rate, "excitation": a.excitation,
             "initial_link_speed": a.initial_speed, "dropout_s": a.dropout, "seed": a.seed, "runs": []}
    moving = a.initial_speed is not None
    for temp, k, c in zip(temps, ks, cs):
        for i, f in enumerate(freqs):
            motor, described = excitation(a.excitation, a.amplitude, f, a.duration, rng, moving)
            p = {"stiffness": k, "damping": c, "inertia": a.inertia, **effects,
                 "initial_link_angle": motor(0.0)[0], "initial_link_speed": a.initial_speed or 0.0}
            drift = None
            if a.drift > 0.0:
                drift = heating(temp, a.drift, a.duration, a.drift_time_constant or a.duration)
            schedule = transmission_schedule(k, c, temp, drift, effects.get("thermal_lag", 0.0))
            t, link, speed = simulate(p, a.duration, a.dt, motor, schedule)
            ts, ls, vs = t[::stride], link[::stride], speed[::stride]
            ms, vms = np.array([motor(x) for x in ts]).T

            def measure(x):
                y = x + rng.normal(0.0, a.noise, x.shape) if a.noise > 0 else x.copy()
                return np.round(y / a.quantum) * a.quantum if a.quantum > 0 else y

            tm = ts + (rng.uniform(-a.jitter, a.jitter, ts.shape) / a.rate if a.jitter > 0 else 0.0)
            keep = np.ones(ts.shape, dtype=bool)
            if a.dropout > 0:
                start = rng.uniform(0.25, 0.75 - a.dropout / a.duration) * a.duration
                keep = (ts < start) | (ts >= start + a.dropout)
            name = f"run_{temp:g}C_{f:g}Hz.csv" if a.excitation == "sine" else f"run_{temp:g}C_{a.excitation}{i + 1}.csv"
            meta = {"temperature_c": temp, "source": "tests/truth/truth_model.py"}
            if a.declare_inertia:
                meta["link_inertia_kgm2"] = a.inertia
            motor_log, link_log = measure(ms)[keep], measure(ls)[keep]
            columns = {"time_s": tm[keep], "motor_angle_rad": motor_log, "link_angle_rad": link_log}
            if drift is not None:  # the thermocouple read at the encoders' instants, to a millikelvin
                columns["temperature_c"] = np.round([housing_temperature(drift, x) for x in ts[keep]], 3)
            write_run(a.out / name, meta, columns)
            run = {"file": name, "temperature_c": temp, "stiffness": k, "damping": c, "excitation": described}
            if drift is not None:
                run["drift"] = drift
            if a.replay:
                # what the replay needs, kept beside the run (replayed on demand: `replay_rms`)
                kept = np.flatnonzero(keep)
                first = [i for i, j in enumerate(kept) if i == 0 or j != kept[i - 1] + 1]
                np.savez(a.out / (Path(name).stem + ".replay.npz"), time=tm[keep], motor=motor_log, link=link_log,
                         motor_speed=vms[keep], starts=np.array(first),
                         start_angles=ls[kept[first]], start_speeds=vs[kept[first]])
                run["replay_inputs"] = Path(name).stem + ".replay.npz"
            if a.dropout > 0:
                run["dropout_s"] = [float(start), float(start + a.dropout)]
            if a.excitation == "sine":
                run["frequency_hz"] = f
            truth["runs"].append(run)
    truth["dt"] = a.dt
    (a.out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")


if __name__ == "__main__":
    main()
