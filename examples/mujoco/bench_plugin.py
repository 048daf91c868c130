#!/usr/bin/env python3
"""Speed of ThermoVIA joints in MuJoCo, measured in one run: the three-joint arm through the native
plugin (`thermovia.joint`) against the FMU co-simulation, and what one joint costs per step.

Every figure is the median of `--repeats` runs, by the wall clock (the machine is shared: the
fastest run is printed too). Regimes: cold (the transmission linear), heating (the elbow's PCL
warming through its softening, a hot housing, the heater on) and backlash (a 0.02 rad play in every
joint: contact events inside the joint's step).

  1. The arm's touch (move above the table and press) at 1 ms: the co-simulation through fmpy and
     the plugin through the same Python loop (controller in Python every step), the plugin with a
     lean loop (numpy controller), and the plugin under `mujoco.rollout` (the motor torques of the
     Python run replayed in C).
  2. One joint's cost per step: `mj_step` of the arm with three plugin joints against the same arm
     with three plain motors (the same joint damping), controls held, divided by three.
  3. `mujoco.rollout` of 64 copies on 2 threads against 1 thread and serial `mj_step`, and whether
     the threaded result equals serial stepping bit for bit.

    python examples/mujoco/bench_plugin.py --out out/mujoco-bench
"""

from __future__ import annotations

import argparse
import json
import pathlib
import statistics
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import thermovia_mujoco as tm  # noqa: E402
from thermovia_mujoco import mujoco, tj  # noqa: E402

REGIMES = ("cold", "heating", "backlash")


def settings_for(regime: str) -> dict:
    s = {j: tm.JointSettings() for j in tm.JOINTS}
    if regime == "heating":
        s["elbow"] = tm.JointSettings(pcl_c=56.0, parameters={"initial_housing_temperature": 120.0 + tm.ZERO_C})
    if regime == "backlash":
        for j in tm.JOINTS:
            s[j].parameters = {"backlash_width": 0.02}
    return s


def plan_for(regime: str, p: dict) -> tm.Plan:
    first = tm.touch_plan(p, 0.2)
    heater = (lambda t, temps: [0.0, 0.0, 50.0]) if regime == "heating" else None
    return tm.Plan([(0.0, p["home"]), *first[:3]], heater=heater)


def timed(repeats: int, f) -> dict:
    """Median and fastest wall time of f() over `repeats` runs, s."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return {"median_s": statistics.median(times), "fastest_s": min(times)}


def lean_loop(m, settings, plan, duration, h):
    """The plugin arm with the references and heater powers computed beforehand: the controller
    (`PluginArm.drive`, numpy) and mj_step alone, what a user's own loop costs at least. Returns
    (wall seconds, the controls of every step)."""
    m.opt.timestep = h
    d = mujoco.MjData(m)
    cols = [tm.dof(m, j) for j in tm.JOINTS]
    d.qpos[cols] = plan.reference(0.0)
    mujoco.mj_forward(m, d)
    arm = tm.PluginArm(m, d, cols, plan.reference(0.0), settings)
    n = int(round(duration / h))
    refs = np.array([plan.reference(i * h) for i in range(n)])
    power = np.array([plan.heater(i * h, None) if plan.heater else [0.0] * 3 for i in range(n)])
    ctrl = np.empty((n, m.nu))
    t0 = time.perf_counter()
    for i in range(n):
        arm.drive(m, d, i * h, h, refs[i], power[i])
        ctrl[i] = d.ctrl
        mujoco.mj_step(m, d)
    return time.perf_counter() - t0, ctrl


def plain_arm_xml(settings) -> str:
    """arm3.xml with a plain motor on each joint and the plugin arm's joint damping: the same scene
    without ThermoVIA."""
    import xml.etree.ElementTree as ET

    plugin_root = ET.fromstring(tm.plugin_arm_xml(tm.DEFAULT_MODEL, settings))
    root = ET.parse(tm.DEFAULT_MODEL).getroot()
    damping = {e.get("name"): e.get("damping") for e in plugin_root.iter("joint")}
    for e in root.iter("joint"):
        e.set("damping", damping[e.get("name")])
    actuator = ET.SubElement(root, "actuator")
    for j in tm.JOINTS:
        ET.SubElement(actuator, "motor", {"name": j, "joint": j})
        ET.SubElement(actuator, "general", {"name": f"{j}_heater", "joint": j, "gainprm": "0", "biasprm": "0"})
    return ET.tostring(root, encoding="unicode")


def held_steps(m, ctrl, steps: int, repeats: int, posture) -> dict:
    d = mujoco.MjData(m)
    d.qpos[:3] = posture
    d.ctrl[:] = ctrl
    mujoco.mj_step(m, d, nstep=100)  # warm: the joints placed, tables built
    return timed(repeats, lambda: mujoco.mj_step(m, d, nstep=steps))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n", 1)[1])
    ap.add_argument("--out", type=pathlib.Path, required=True, help="folder for bench.json and bench.md")
    ap.add_argument("--repeats", type=int, default=5, help="runs per figure [%(default)s]")
    ap.add_argument("--step", type=float, default=1e-3, help="MuJoCo step, s [%(default)s]")
    ap.add_argument("--held-steps", type=int, default=20000, help="steps per run of the per-joint cost [%(default)s]")
    args = ap.parse_args(argv)
    from mujoco import rollout

    h = args.step
    arm0 = tm.load_arm(tm.DEFAULT_MODEL)
    p = tm.postures(arm0)
    unzipdir, md = tm.open_fmu(tm.DEFAULT_FMU)
    result = {"step_s": h, "repeats": args.repeats, "regimes": {}}
    for regime in REGIMES:
        settings = settings_for(regime)
        plan = plan_for(regime, p)
        duration = plan.waypoints[-1][0]
        steps = int(round(duration / h))
        r = {"simulated_s": duration, "steps": steps}
        r["cosim_python"] = timed(args.repeats, lambda: tm.run_cosim(tm.load_arm(tm.DEFAULT_MODEL), unzipdir, md, plan,
                                                                     duration, h, settings, record_every=10**9))
        r["plugin_python"] = timed(args.repeats, lambda: tm.run_plugin(tm.DEFAULT_MODEL, plan, duration, h, settings,
                                                                       record_every=10**9))
        m = tm.load_plugin_arm(tm.DEFAULT_MODEL, settings)
        lean = [lean_loop(m, settings, plan, duration, h) for _ in range(args.repeats)]
        r["plugin_lean_loop"] = {"median_s": statistics.median(x[0] for x in lean), "fastest_s": min(x[0] for x in lean)}
        # the same motor torques replayed in C by mujoco.rollout from the same initial state
        _, ctrl = lean[0]
        m.opt.timestep = h
        d = mujoco.MjData(m)
        cols = [tm.dof(m, j) for j in tm.JOINTS]
        d.qpos[cols] = plan.reference(0.0)
        mujoco.mj_forward(m, d)
        tm.PluginArm(m, d, cols, plan.reference(0.0), settings)
        x0 = tj.full_state(m, d)
        r["plugin_rollout"] = timed(args.repeats, lambda: rollout.rollout(m, d, x0, ctrl))
        for key in ("cosim_python", "plugin_python", "plugin_lean_loop", "plugin_rollout"):
            r[key]["steps_per_s"] = steps / r[key]["median_s"]
            r[key]["real_time_factor"] = duration / r[key]["median_s"]
        # one joint's cost: the plugin arm against the plain arm, controls held at a press
        plain = mujoco.MjModel.from_xml_string(plain_arm_xml(settings))
        plain.opt.timestep = m.opt.timestep = h
        def held(model):
            u = np.zeros(model.nu)
            for j, torque in zip(tm.JOINTS, (0.0, 1.0, 0.5)):
                u[model.actuator(j).id] = torque
            u[model.actuator("elbow_heater").id] = 50.0 if regime == "heating" else 0.0
            return u

        with_joints = held_steps(m, held(m), args.held_steps, args.repeats, p["press"])
        without = held_steps(plain, held(plain), args.held_steps, args.repeats, p["press"])
        r["mj_step_with_plugin_us"] = 1e6 * with_joints["median_s"] / args.held_steps
        r["mj_step_plain_us"] = 1e6 * without["median_s"] / args.held_steps
        r["one_joint_us"] = (r["mj_step_with_plugin_us"] - r["mj_step_plain_us"]) / 3
        result["regimes"][regime] = r
        print(f"{regime}: co-sim {r['cosim_python']['real_time_factor']:.1f}x real time, plugin (Python loop) "
              f"{r['plugin_python']['real_time_factor']:.1f}x, lean {r['plugin_lean_loop']['real_time_factor']:.1f}x, "
              f"rollout {r['plugin_rollout']['real_time_factor']:.1f}x; one joint {r['one_joint_us']:.3f} us/step")

    # 64 copies on 2 threads, 1 thread, and serial mj_step; bit-identical?
    settings = settings_for("cold")
    m = tm.load_plugin_arm(tm.DEFAULT_MODEL, settings)
    m.opt.timestep = h
    d = mujoco.MjData(m)
    d.qpos[:3] = p["above"]
    mujoco.mj_step(m, d, nstep=10)
    x0 = tj.full_state(m, d)
    rng = np.random.default_rng(0)
    copies, steps = 64, 500
    initial = np.tile(x0, (copies, 1))
    initial[:, 1:4] += rng.uniform(-0.05, 0.05, (copies, 3))
    control = np.zeros((copies, steps, m.nu))
    control[:, :, [m.actuator(j).id for j in tm.JOINTS]] = rng.uniform(-0.5, 0.5, (copies, 1, 3)) + np.array([0.0, 2.5, 0.6])
    datas = [mujoco.MjData(m) for _ in range(2)]
    two = timed(args.repeats, lambda: rollout.rollout([m] * copies, datas, initial, control))
    one = timed(args.repeats, lambda: rollout.rollout([m] * copies, datas[:1], initial, control))
    threaded, _ = rollout.rollout([m] * copies, datas, initial, control)
    ser = timed(args.repeats, lambda: tj.step_serially(m, d, initial, control))
    serial = tj.step_serially(m, d, initial, control)
    result["rollout_64"] = {
        "copies": copies, "steps": steps,
        "two_threads": two, "one_thread": one, "serial_python_mj_step": ser,
        "speedup_two_threads_over_one": one["median_s"] / two["median_s"],
        "bit_identical_to_serial": threaded.tobytes() == serial.tobytes(),
    }
    print(f"rollout 64x{steps}: 2 threads {two['median_s']:.3f} s, 1 thread {one['median_s']:.3f} s, serial "
          f"{ser['median_s']:.3f} s; bit-identical: {result['rollout_64']['bit_identical_to_serial']}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "bench.json").write_text(json.dumps(result, indent=2) + "\n")
    (args.out / "bench.md").write_text(markdown(result))
    print(f"bench_plugin: wrote {args.out}/bench.md")
    return 0


def markdown(r: dict) -> str:
    s = [f"# ThermoVIA joints in MuJoCo: speed (step {r['step_s'] * 1e3:g} ms, median of {r['repeats']} runs)\n",
         "| regime | co-simulation (fmpy), × real time | plugin, same Python loop | plugin, lean loop | plugin, mujoco.rollout | "
         "rollout / co-simulation | mj_step with 3 joints (µs) | without (µs) | one joint (µs/step) |",
         "|---|---|---|---|---|---|---|---|---|"]
    for name, x in r["regimes"].items():
        co = x["cosim_python"]["real_time_factor"]
        s.append(f"| {name} | {co:.1f} | {x['plugin_python']['real_time_factor']:.1f} | "
                 f"{x['plugin_lean_loop']['real_time_factor']:.1f} | {x['plugin_rollout']['real_time_factor']:.0f} | "
                 f"{x['plugin_rollout']['real_time_factor'] / co:.0f}× | {x['mj_step_with_plugin_us']:.2f} | "
                 f"{x['mj_step_plain_us']:.2f} | {x['one_joint_us']:.3f} |")
    ro = r["rollout_64"]
    s.append(f"\n`mujoco.rollout` of {ro['copies']} copies × {ro['steps']} steps: 2 threads "
             f"{ro['two_threads']['median_s']:.3f} s, 1 thread {ro['one_thread']['median_s']:.3f} s "
             f"({ro['speedup_two_threads_over_one']:.2f}×), serial mj_step from Python {ro['serial_python_mj_step']['median_s']:.3f} s; "
             f"threaded equals serial bit for bit: {'yes' if ro['bit_identical_to_serial'] else 'NO'}.\n")
    return "\n".join(s)


if __name__ == "__main__":
    sys.exit(main())
