"""The default sweep driven by fmpy's low-level FMU2Slave API, with the same master as the Rust
harness (src/sweep/master.rs): motor PD + feedforward, heater PI on the housing temperature,
coarse-step warm-up with the motor at rest, one saved warm-up state shared by both frequencies.

Used by `cargo bench --bench sweep` to time the same sweep through fmpy; prints one JSON object:
{"median_s": ..., "times_s": [...], "conditions": [{"temperature_c", "frequency_hz", "h_re", "h_im"}]}

    .venv/bin/python tests/python/sweep_fmpy_bench.py target/fmu/ThermoVIA.fmu --repeat 3
"""

import argparse
import json
import math
import shutil
import time

import fmpy
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

ZERO_CELSIUS = 273.15
OUTPUTS = [
    "motor_angle", "motor_speed", "link_angle", "link_speed", "housing_temperature", "pcl_temperature",
    "effective_stiffness", "effective_damping", "storage_modulus", "loss_modulus", "heater_energy",
]

# the Rust defaults (SweepArgs)
DEFAULTS = dict(temperatures=[22.0, 40.0, 50.0, 60.0], frequencies=[0.5, 1.0], amplitude_rad=math.pi / 6, step=1e-3,
                settle_cycles=6, cycles=4, motor_kp=400.0, motor_kd=3.0, heater_max_w=10.0, heater_kp=4.0,
                heater_ki=0.2, warmup_step=0.1, soak=600.0, reach_tolerance=0.5)


class Heater:
    def __init__(self, target_k, kp, ki, p_max):
        self.target_k, self.kp, self.ki, self.p_max, self.integral = target_k, kp, ki, p_max, 0.0

    def power(self, housing_k, h):
        e = self.target_k - housing_k
        raw = self.kp * e + self.integral
        p = min(max(raw, 0.0), self.p_max)
        if (raw < self.p_max or e < 0.0) and (raw > 0.0 or e > 0.0):
            self.integral += self.ki * e * h
        return p


class Sim:
    """One FMU instance with a clock, as the Rust harness's Instance."""

    def __init__(self, md, unzipdir, name, params):
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        for k, v in params.items():
            self.fmu.setReal([self.vr[k]], [v])
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.time = 0.0
        self.out = [self.vr[n] for n in OUTPUTS]

    def step(self, h):
        self.fmu.doStep(currentCommunicationPoint=self.time, communicationStepSize=h)
        self.time += h

    def outputs(self):
        return self.fmu.getReal(self.out)

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def warm_up(sim, heater, h, steps, tol, reached):
    y = sim.outputs()
    sim.fmu.setReal([sim.vr["motor_torque"]], [0.0])
    hp = sim.vr["heater_power"]
    for _ in range(steps):
        sim.fmu.setReal([hp], [heater.power(y[4], h)])
        sim.step(h)
        y = sim.outputs()
        if abs(heater.target_k - y[4]) <= tol:
            reached = True
    return reached


def harmonic_run(sim, a, omega, kp, kd, jm, bm, heater, h, steps):
    vrs = [sim.vr["motor_torque"], sim.vr["heater_power"]]
    y = sim.outputs()
    motor, link = np.empty(steps + 1), np.empty(steps + 1)
    motor[0], link[0] = y[0], y[2]
    for k in range(steps):
        t = k * h
        s, c = math.sin(omega * t), math.cos(omega * t)
        r, rd, rdd = a * s, a * omega * c, -a * omega * omega * s
        tau = jm * rdd + bm * rd + kp * (r - y[0]) + kd * (rd - y[1])
        p = heater.power(y[4], h) if heater else 0.0
        sim.fmu.setReal(vrs, [tau, p])
        sim.step(h)
        y = sim.outputs()
        motor[k + 1], link[k + 1] = y[0], y[2]
    return motor, link


def first_harmonic(t, x, omega):
    return 2.0 / len(x) * complex(np.sum(x * np.sin(omega * t)), np.sum(x * np.cos(omega * t)))


def sweep(fmu_path, o=DEFAULTS, md=None, unzipdir=None):
    md = md or read_model_description(fmu_path)
    own = unzipdir is None
    unzipdir = unzipdir or extract(fmu_path)
    results = []
    try:
        for temp_c in o["temperatures"]:
            sim = Sim(md, unzipdir, f"sweep{temp_c}", {"excitation_frequency": o["frequencies"][0],
                                                       "max_internal_step": max(o["warmup_step"], o["step"])})
            jm, bm = sim.fmu.getReal([sim.vr["motor_inertia"], sim.vr["motor_damping"]])
            ambient_c = sim.fmu.getReal([sim.vr["ambient_temperature"]])[0] - ZERO_CELSIUS
            heater = Heater(temp_c + ZERO_CELSIUS, o["heater_kp"], o["heater_ki"], o["heater_max_w"])
            if temp_c > ambient_c + o["reach_tolerance"]:
                hw, chunk = o["warmup_step"], int(round(10.0 / o["warmup_step"]))
                reached, elapsed = False, 0
                while not reached and elapsed * hw < 3600.0:
                    reached = warm_up(sim, heater, hw, chunk, o["reach_tolerance"], reached)
                    elapsed += chunk
                warm_up(sim, heater, hw, int(round(o["soak"] / hw)), o["reach_tolerance"], True)
            else:
                heater = None
            saved = sim.fmu.getFMUstate()
            saved_time = sim.time
            saved_integral = heater.integral if heater else 0.0
            for f in o["frequencies"]:
                sim.fmu.setFMUstate(saved)
                sim.time = saved_time
                if heater:
                    heater.integral = saved_integral
                sim.fmu.setReal([sim.vr["excitation_frequency"]], [f])
                omega = 2.0 * math.pi * f
                n = int(round(1.0 / (f * o["step"])))
                steps = n * (o["settle_cycles"] + o["cycles"])
                motor, link = harmonic_run(sim, o["amplitude_rad"], omega, o["motor_kp"], o["motor_kd"],
                                           jm, bm, heater, o["step"], steps)
                t = np.arange(steps + 1) * o["step"]
                w = slice(len(t) - n * o["cycles"], len(t))
                cm, cl = first_harmonic(t[w], motor[w], omega), first_harmonic(t[w], link[w], omega)
                h = cl / cm
                results.append({"temperature_c": temp_c, "frequency_hz": f, "h_re": h.real, "h_im": h.imag,
                                "decay_rad": abs(cm) - abs(cl), "phase_deg": -math.degrees(math.atan2(h.imag, h.real))})
            sim.fmu.freeFMUstate(saved)
            sim.free()
    finally:
        if own:
            shutil.rmtree(unzipdir, ignore_errors=True)
    return results


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("fmu")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    times, results = [], None
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        results = sweep(args.fmu)
        times.append(time.perf_counter() - t0)
    print(json.dumps({"median_s": float(np.median(times)), "times_s": times, "fmpy_version": fmpy.__version__,
                      "conditions": results}))


if __name__ == "__main__":
    main()
