"""ThermoVIA in fmpy with a hand-written co-simulation loop.

Two instances of the same FMU in one process: a cold joint (22 °C) and a heated one (PCL held at
60 °C by its heater). Each carries a link with a 0.91 kg mass at 0.14 m in a vertical plane (the
paper's set-up) and lifts it from hanging at -60° to horizontal. The loop is what fmpy users write:
set inputs, doStep, get outputs. Gravity lives on the master side and enters through `load_torque`;
the FMU's `link_inertia` is the whole link, so the coupling needs nothing else. The joint
controller is a PD on the motor angle with gravity feed-forward, aimed at the link angle plus the
spring's deflection under gravity g(q*)/K_eff (K_eff read from the FMU, so it follows the heating).

    python examples/python/closed_loop.py [path/to/ThermoVIA.fmu]

Build the FMU first: cargo run --release -p fmu-build
"""

import math
import sys
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

DEFAULT_FMU = Path(__file__).resolve().parents[2] / "target" / "fmu" / "ThermoVIA.fmu"
G = 9.80665
MASS, ARM = 0.91, 0.14            # kg at m: the paper's link
LINK_INERTIA = MASS * ARM**2 + 1e-3  # + the output hub
KP, KD = 150.0, 1.5               # N·m/rad, N·m·s/rad on the motor angle
START, GOAL = math.radians(-60.0), 0.0
ROOM_K = 295.15


def gravity(q):
    """Torque of gravity about the joint needed to hold the link at q (q = 0: horizontal)."""
    return MASS * G * ARM * math.cos(q)


def plan(t, t0=0.2, duration=0.6):
    """Minimum-jerk move from START to GOAL; returns (angle, speed)."""
    s = min(max((t - t0) / duration, 0.0), 1.0)
    pos = s**3 * (10 - 15 * s + 6 * s * s)
    vel = 30 * s * s * (1 - s) ** 2 / duration if 0 < s < 1 else 0.0
    return START + (GOAL - START) * pos, (GOAL - START) * vel


class Joint:
    """One ThermoVIA instance with the value references the loop uses."""

    def __init__(self, md, unzipdir, name, pcl_c, stiffness_guess):
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        t = 273.15 + pcl_c
        # start at rest: link hanging at START, motor ahead by the spring's deflection
        params = {"link_inertia": LINK_INERTIA, "initial_pcl_temperature": t, "initial_housing_temperature": t,
                  "initial_link_angle": START, "initial_motor_angle": START + gravity(START) / stiffness_guess}
        self.fmu.setReal([self.vr[k] for k in params], list(params.values()))
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        g_loss = self.fmu.getReal([self.vr["housing_ambient_conductance"]])[0]
        self.heater = g_loss * (t - ROOM_K)  # W that balance the passive loss at this temperature
        self.inputs = [self.vr[n] for n in ("motor_torque", "load_torque", "heater_power")]
        self.outputs = [self.vr[n] for n in ("link_angle", "link_speed", "motor_angle", "motor_speed",
                                             "transmitted_torque", "effective_stiffness", "pcl_temperature")]

    def read(self):
        return self.fmu.getReal(self.outputs)

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def stiffness_at(md, unzipdir, pcl_c):
    """K_eff of a joint at a PCL temperature, read from a throw-away instance."""
    j = Joint(md, unzipdir, "probe", pcl_c, 1.0)
    k = j.read()[5]
    j.close()
    return k


def run(fmu_path=DEFAULT_FMU, step=1e-3, duration=2.0, temperatures=(("cold", 22.0), ("hot", 60.0))):
    md = read_model_description(str(fmu_path))
    unzipdir = extract(str(fmu_path))
    joints = {name: Joint(md, unzipdir, name, c, stiffness_at(md, unzipdir, c)) for name, c in temperatures}
    log = {name: [] for name in joints}
    t = 0.0
    for _ in range(int(round(duration / step))):
        q_star, v_star = plan(t)
        for name, j in joints.items():
            q, v, th, thd, tau, k, pcl = j.read()
            log[name].append((t, q, th, tau, k, pcl))
            target = q_star + gravity(q_star) / k
            motor = KP * (target - th) + KD * (v_star - thd) + gravity(q_star)
            load = -gravity(q)  # held over the step: one-step delay, exact otherwise
            j.fmu.setReal(j.inputs, [motor, load, j.heater])
        for j in joints.values():  # Jacobi: every instance steps from the same t
            j.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=step)
        t += step
    results = {}
    for name, j in joints.items():
        q, v, th, thd, tau, k, pcl = j.read()
        peak = max(abs(r[1] - plan(r[0])[0]) for r in log[name])
        results[name] = {"link_angle": q, "motor_angle": th, "transmitted_torque": tau, "stiffness": k,
                         "pcl_temperature_c": pcl - 273.15, "deflection": th - q, "gravity": gravity(q),
                         "max_tracking_error": peak, "log": log[name]}
        j.close()
    return results


if __name__ == "__main__":
    res = run(sys.argv[1] if len(sys.argv) > 1 else DEFAULT_FMU)
    print(f"{'joint':6} {'PCL °C':>7} {'K N·m/rad':>10} {'final q °':>10} {'deflection °':>13} {'max tracking error °':>21}")
    for name, r in res.items():
        print(f"{name:6} {r['pcl_temperature_c']:7.1f} {r['stiffness']:10.2f} {math.degrees(r['link_angle']):10.4f} "
              f"{math.degrees(r['deflection']):13.3f} {math.degrees(r['max_tracking_error']):21.3f}")
