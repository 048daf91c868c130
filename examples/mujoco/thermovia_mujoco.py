#!/usr/bin/env python3
"""ThermoVIA joints inside MuJoCo: a three-joint arm whose every joint is a ThermoVIA FMU instance.

MuJoCo integrates the links, gravity and contact; each FMU, in link-driven mode (`link_drive` = 1),
integrates its joint's motor, spring + PCL transmission and heat. The FMU is a force element, the
causality rigid-body engines expect: no `link_inertia` trick, no inertia counted twice.

Coupling, per communication step [t, t + h] (one MuJoCo step of h):
  1. engine -> FMU: the joint's angle q(t) and speed q'(t); the link follows q(t) + q'(t) s over
     the step (`link_angle_command`, `link_speed_command`: the speed is held).
  2. master -> FMU: the motor torque of the joint controller (PD on the motor angle, plus the link's
     gravity and velocity torques as feed-forward), held; the heater power.
  3. FMU -> engine: `transmitted_torque_mean`, the transmission's impulse over the step divided by h
     (from the motor's momentum balance, exact). MuJoCo applies it on the joint over its step
     (`qfrc_applied`), so the link receives the impulse the FMU integrated. One part of it is handed
     to MuJoCo's implicit integrator instead: the transmission's damping on the link, C_eff
     (`effective_damping`), becomes the joint's damping for the step and C_eff q'(t) is added back
     to the applied torque, so the engine takes −C_eff q'(t + h). Without that, a light link on a
     well-damped PCL (C/J ~ 2000 1/s on the base joint) limits the step to 2J/C < 1 ms; with it the
     explicit part of the coupling is the stiffness alone. The joint torque acts between parent and
     link, so the parent takes its reaction; the rotor's own inertial reaction on the parent
     (J_m θm'') is not applied: it stays inside the FMU, as a rotor's inertia does in MuJoCo's
     `armature`, the convention the monolithic comparison shares.
The link path the FMU assumed (straight at q'(t)) and the one MuJoCo then integrates differ by
O(h^2) per step: the coupling is first order in h, and explicit. Stability limit: see
`stability_limit` (the linearised coupled map of motor, transmission, sampled PD and semi-implicit
Euler link, per joint, at its smallest effective inertia and at the cold and hot transmissions).

Usage (the README's one command builds the FMU and the venv first: scripts/run-mujoco.sh):
    python examples/mujoco/thermovia_mujoco.py --out out/mujoco
    python examples/mujoco/thermovia_mujoco.py --help
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import shutil
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

os.environ.setdefault("MUJOCO_GL", "osmesa")

import numpy as np  # noqa: E402


def _import_mujoco():
    """MuJoCo, and why rendering is off when its GL backend cannot load (a missing OSMesa or EGL,
    a bad MUJOCO_GL): the simulation needs no GL, so it goes on without frames."""
    try:
        import mujoco

        return mujoco, None
    except (RuntimeError, ImportError, OSError) as e:
        for name in [n for n in sys.modules if n == "mujoco" or n.startswith("mujoco.")]:
            del sys.modules[name]
        why = f"off-screen rendering unavailable (MUJOCO_GL={os.environ.get('MUJOCO_GL')}: {e})"
        os.environ["MUJOCO_GL"] = "disable"
        import mujoco

        return mujoco, why


mujoco, GL_PROBLEM = _import_mujoco()

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
sys.path.insert(0, str(ROOT / "crates" / "mujoco" / "python"))
import thermovia_joint as tj  # noqa: E402
DEFAULT_FMU = ROOT / "target" / "fmu" / "ThermoVIA.fmu"
DEFAULT_MODEL = HERE / "arm3.xml"
JOINTS = ("base_yaw", "shoulder", "elbow")
ZERO_C = 273.15
ROOM_C = 22.0


class CouplingError(Exception):
    """Bad input to the example: the message says what and where."""


# ---------------------------------------------------------------------------------------------
# the engine side


def load_arm(xml_path: pathlib.Path, joints=JOINTS):
    """The MuJoCo model, with every named joint checked to exist and be a hinge."""
    if not pathlib.Path(xml_path).exists():
        raise CouplingError(f"{xml_path}: no such model file")
    try:
        m = mujoco.MjModel.from_xml_path(str(xml_path))
    except ValueError as e:
        raise CouplingError(f"{xml_path}: MuJoCo cannot read it: {e}") from e
    names = [m.joint(i).name for i in range(m.njnt)]
    missing = [j for j in joints if j not in names]
    if missing:
        raise CouplingError(
            f"{xml_path}: no joint named {', '.join(missing)} (the model's joints: {', '.join(names) or 'none'}); "
            f"each ThermoVIA actuator needs a hinge joint of that name"
        )
    for j in joints:
        if m.joint(j).type[0] != mujoco.mjtJoint.mjJNT_HINGE:
            raise CouplingError(f"{xml_path}: joint {j} is not a hinge (a ThermoVIA joint is rotary)")
    return m


def dof(m, joint: str) -> int:
    return int(m.joint(joint).dofadr[0])


def effective_inertias(m, joints=JOINTS, samples: int = 7) -> dict:
    """Smallest effective inertia 1/(M^-1)_ii each joint shows over a grid of postures: what the
    explicit coupling's stability depends on (the link as the FMU's force sees it)."""
    d = mujoco.MjData(m)
    out = {j: math.inf for j in joints}
    grids = [np.linspace(-1.5, 1.5, samples) for _ in range(m.nq)]
    for idx in np.ndindex(*(samples,) * min(m.nq, 3)):
        d.qpos[:] = 0.0
        for k, i in enumerate(idx):
            d.qpos[k] = grids[k][i]
        mujoco.mj_forward(m, d)
        minv = np.zeros((m.nv, m.nv))
        mujoco.mj_solveM(m, d, minv, np.eye(m.nv))
        for j in joints:
            i = dof(m, j)
            out[j] = min(out[j], 1.0 / minv[i, i])
    return out


def contact_force(m, d, geom_a: str, geom_b: str) -> float:
    """Normal force between two geoms, N (0 when apart)."""
    a, b = m.geom(geom_a).id, m.geom(geom_b).id
    total = 0.0
    f = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        if {c.geom1, c.geom2} == {a, b}:
            mujoco.mj_contactForce(m, d, i, f)
            total += f[0]
    return total


def solve_ik(m, target, q0, site="tip", joints=JOINTS, iterations=500):
    """Joint angles that put `site` at `target` (damped least squares)."""
    d = mujoco.MjData(m)
    q = np.array(q0, dtype=float)
    cols = [dof(m, j) for j in joints]
    for _ in range(iterations):
        d.qpos[cols] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        err = np.asarray(target) - d.site(site).xpos
        if np.linalg.norm(err) < 1e-7:
            break
        jp = np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, d, jp, None, m.site(site).id)
        jac = jp[:, cols]
        dq = jac.T @ np.linalg.solve(jac @ jac.T + 1e-8 * np.eye(3), err)
        q += dq * min(1.0, 0.1 / max(np.abs(dq).max(), 1e-300))
    return q


# ---------------------------------------------------------------------------------------------
# the FMU side


@dataclass
class JointSettings:
    kp: float = 150.0  # N·m/rad on the motor angle (thermovia arm's default)
    kd: float = 1.5  # N·m·s/rad
    pcl_c: float = ROOM_C  # initial PCL and housing temperature, °C
    parameters: dict = field(default_factory=dict)


def pd_torque(kp, kd, motor_angle, motor_speed, stiffness, q_ref, feedforward):
    """The joint controller: PD on the motor angle, its reference raised by the transmission's
    deflection under the feed-forward (feedforward / K_eff at the joint's current temperature), plus
    the feed-forward. Scalars, or numpy arrays for several joints at once."""
    target = q_ref + feedforward / stiffness
    return kp * (target - motor_angle) - kd * motor_speed + feedforward


class FmuJoint:
    """One ThermoVIA FMU instance in link-driven mode at one MuJoCo hinge, through fmpy."""

    OUT = (
        "transmitted_torque_mean",
        "motor_angle",
        "motor_speed",
        "pcl_temperature",
        "effective_stiffness",
        "effective_damping",
        "link_angle",
    )

    def __init__(self, unzipdir: str, md, name: str, settings: JointSettings, q0: float, t0: float = 0.0,
                 motor0: float | None = None):
        from fmpy.fmi2 import FMU2Slave

        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.settings = settings
        self.fmu = FMU2Slave(
            guid=md.guid,
            unzipDirectory=unzipdir,
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName=name,
        )
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=t0)
        self.fmu.enterInitializationMode()
        self.fmu.setInteger([self.vr["link_drive"]], [1])
        temp = settings.pcl_c + ZERO_C
        reals = {
            "initial_pcl_temperature": temp,
            "initial_housing_temperature": temp,
            "initial_motor_angle": q0 if motor0 is None else motor0,
            "initial_link_angle": q0,
            "ambient_temperature": ROOM_C + ZERO_C,
            **settings.parameters,
        }
        self.fmu.setReal([self.vr[k] for k in reals], list(reals.values()))
        self.fmu.exitInitializationMode()
        self.in_vr = [self.vr[k] for k in ("link_angle_command", "link_speed_command", "motor_torque", "heater_power")]
        self.out_vr = [self.vr[k] for k in self.OUT]
        self.y = dict(zip(self.OUT, self.fmu.getReal(self.out_vr)))
        self.fmu_seconds = 0.0
        self.call_seconds = 0.0

    def parameter(self, name: str) -> float:
        return self.fmu.getReal([self.vr[name]])[0]

    def motor_torque(self, q_ref: float, feedforward: float) -> float:
        s, y = self.settings, self.y
        return pd_torque(s.kp, s.kd, y["motor_angle"], y["motor_speed"], y["effective_stiffness"], q_ref, feedforward)

    def step(self, t: float, h: float, q: float, qd: float, tau_m: float, heater: float) -> float:
        c0 = time.perf_counter()
        self.fmu.setReal(self.in_vr, [q, qd, tau_m, heater])
        c1 = time.perf_counter()
        status = self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        c2 = time.perf_counter()
        if status not in (0, None):
            raise CouplingError(f"fmi2DoStep at t = {t:.4f} s returned status {status}")
        self.y = dict(zip(self.OUT, self.fmu.getReal(self.out_vr)))
        c3 = time.perf_counter()
        self.fmu_seconds += c2 - c1
        self.call_seconds += (c1 - c0) + (c3 - c2)
        return self.y["transmitted_torque_mean"]

    def apply(self, m, d, dof_index: int, tau: float) -> None:
        """Hands the step's mean torque to MuJoCo on the joint's dof. The transmission's damping on the
        link goes to MuJoCo's implicit joint damping: the FMU's torque at the step's start speed is
        given back (C_eff q'(t)), and the engine takes −C_eff q'(t + h)."""
        damping = self.y["effective_damping"]
        m.dof_damping[dof_index] = damping
        d.qfrc_applied[dof_index] += tau + damping * d.qvel[dof_index]

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def open_fmu(fmu_path: pathlib.Path):
    """(unzip dir, model description) of the packaged FMU."""
    from fmpy import extract, read_model_description

    if not pathlib.Path(fmu_path).exists():
        raise CouplingError(f"{fmu_path}: no FMU there (build it: cargo run --release -p fmu-build)")
    md = read_model_description(str(fmu_path))
    names = {v.name for v in md.modelVariables}
    for needed in ("link_drive", "link_angle_command", "link_speed_command", "transmitted_torque_mean"):
        if needed not in names:
            raise CouplingError(f"{fmu_path}: the FMU has no {needed}: it predates the link-driven mode")
    return extract(str(fmu_path)), md


# ---------------------------------------------------------------------------------------------
# stability of the explicit coupling


def coupled_map(h, k, c, j_link, j_motor, b_motor, kp, kd, substeps=64):
    """4x4 map of [θm, θm', q, q'] over one communication step of the linearised joint: PD sampled
    and held, motor + Kelvin–Voigt transmission exact over the step with the link on q + q' s (RK4
    on fine substeps stands in for the FMU's exact step), then MuJoCo's semi-implicit Euler on the
    link with the mean transmission torque, its damping C taken implicitly (see the module's
    coupling note)."""
    cols = []
    for e in np.eye(4):
        th, w, q, qd = e
        tau_m = -kp * th - kd * w
        dt = h / substeps
        impulse = 0.0

        def f(s, th, w):
            tau = k * (th - (q + qd * s)) + c * (w - qd)
            return w, (tau_m - b_motor * w - tau) / j_motor, tau

        for i in range(substeps):
            s0 = i * dt
            k1 = f(s0, th, w)
            k2 = f(s0 + dt / 2, th + dt / 2 * k1[0], w + dt / 2 * k1[1])
            k3 = f(s0 + dt / 2, th + dt / 2 * k2[0], w + dt / 2 * k2[1])
            k4 = f(s0 + dt, th + dt * k3[0], w + dt * k3[1])
            th, w = th + dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]), w + dt / 6 * (
                k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]
            )
            impulse += dt / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        qd_next = (qd + (impulse + c * qd * h) / j_link) / (1.0 + h * c / j_link)
        cols.append([th, w, q + h * qd_next, qd_next])
    return np.array(cols).T


def stable(h, **kw) -> bool:
    return max(abs(np.linalg.eigvals(coupled_map(h, **kw)))) < 1.0


def stability_limit(k, c, j_link, j_motor, b_motor, kp, kd) -> float:
    """Largest communication step at which the linearised coupled map is stable (bisection), s."""
    kw = dict(k=k, c=c, j_link=j_link, j_motor=j_motor, b_motor=b_motor, kp=kp, kd=kd)
    lo, hi = 1e-6, 1e-6
    while stable(hi, **kw) and hi < 1.0:
        lo, hi = hi, hi * 2
    if hi >= 1.0:
        return 1.0
    for _ in range(40):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if stable(mid, **kw) else (lo, mid)
    return lo


def transmission_at(unzipdir, md, temp_c: float) -> tuple:
    """(K_eff, C_eff, J_m, B_m) of the FMU's transmission at a steady temperature."""
    j = FmuJoint(unzipdir, md, "probe", JointSettings(pcl_c=temp_c), 0.0)
    try:
        return (j.y["effective_stiffness"], j.y["effective_damping"], j.parameter("motor_inertia"), j.parameter("motor_damping"))
    finally:
        j.close()


def check_step(m, unzipdir, md, h: float, settings: dict, hot_c: float = 62.0) -> dict:
    """Each joint's stability limit (cold and hot transmission, its smallest effective inertia);
    raises CouplingError when h is at or above the smallest."""
    inertias = effective_inertias(m)
    limits = {}
    for temp in (ROOM_C, hot_c):
        k, c, jm, bm = transmission_at(unzipdir, md, temp)
        for name in JOINTS:
            s = settings[name]
            lim = stability_limit(k, c, inertias[name], jm, bm, s.kp, s.kd)
            key = f"{name} at {temp:.0f} °C"
            limits[key] = {"limit_s": lim, "stiffness": k, "damping": c, "link_inertia": inertias[name]}
    worst = min(limits, key=lambda k: limits[k]["limit_s"])
    limit = limits[worst]["limit_s"]
    if h >= limit:
        raise CouplingError(
            f"coupling step {h:g} s is at or above the stability limit {limit:.4g} s ({worst}: K = "
            f"{limits[worst]['stiffness']:.3g} N·m/rad, C = {limits[worst]['damping']:.3g} N·m·s/rad, smallest effective "
            f"link inertia {limits[worst]['link_inertia']:.3g} kg·m²); use a step below it"
        )
    return {"limit_s": limit, "limiting": worst, "per_joint": limits}


# ---------------------------------------------------------------------------------------------
# the task


@dataclass
class Plan:
    """Joint references (piecewise minimum-jerk between postures) and heater powers over time."""

    waypoints: list  # [(t, posture)]
    heater: object = None  # (t, pcl temperatures °C) -> [W per joint]

    def reference(self, t: float) -> np.ndarray:
        w = self.waypoints
        if t <= w[0][0]:
            return np.array(w[0][1])
        for (t0, q0), (t1, q1) in zip(w, w[1:]):
            if t <= t1:
                s = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
                s = s * s * s * (10 - 15 * s + 6 * s * s)
                return np.array(q0) + s * (np.array(q1) - np.array(q0))
        return np.array(w[-1][1])


def postures(m) -> dict:
    """Home, above the table and pressing into it (3 cm past the surface), by inverse kinematics."""
    home = np.array([0.0, 0.9, -1.6])
    table_top = 0.16
    radius = m.geom("tip").size[0]
    above = solve_ik(m, [0.40, 0.06, table_top + radius + 0.05], home)
    press = solve_ik(m, [0.40, 0.06, table_top + radius - 0.03], above)
    return {"home": home, "above": above, "press": press}


def touch_plan(p: dict, start: float = 0.0) -> list:
    """Waypoints of one touch from `start`: to above, press, hold, lift (s)."""
    s = start
    return [
        (s + 0.0, p["above"]),
        (s + 0.5, p["press"]),
        (s + 1.2, p["press"]),
        (s + 1.6, p["above"]),
    ]


@dataclass
class Record:
    t: list = field(default_factory=list)
    q: list = field(default_factory=list)
    torque: list = field(default_factory=list)
    pcl_c: list = field(default_factory=list)
    stiffness: list = field(default_factory=list)
    contact: list = field(default_factory=list)
    frames: list = field(default_factory=list)  # (t, label, rgb array)
    # each touch's first contact: {t, approach_speed_m_s (the tip's downward speed the step before),
    # peak_force_n (largest over its first 0.1 s), bounces (contacts lost and made again within 0.2 s)}
    impacts: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)

    def arrays(self) -> dict:
        return {k: np.array(v) for k, v in self.__dict__.items() if k not in ("frames", "impacts", "seconds")}


class FmuArm:
    """The arm's joints as FMU instances in link-driven mode, through fmpy: the co-simulation."""

    def __init__(self, m, d, cols, q0, unzipdir, md, settings: dict):
        self.cols = cols
        # each motor starts where the link is in equilibrium: deflected by its gravity torque over K_eff
        stiffness = {t: transmission_at(unzipdir, md, t)[0] for t in {settings[j].pcl_c for j in JOINTS}}
        self.joints = [
            FmuJoint(unzipdir, md, j, settings[j], float(q0[i]),
                     motor0=float(q0[i] + d.qfrc_bias[cols[i]] / stiffness[settings[j].pcl_c]))
            for i, j in enumerate(JOINTS)
        ]
        self.last = [0.0] * len(JOINTS)

    def temperatures_c(self, d) -> list:
        return [j.y["pcl_temperature"] - ZERO_C for j in self.joints]

    def stiffnesses(self, d) -> list:
        return [j.y["effective_stiffness"] for j in self.joints]

    def drive(self, m, d, t: float, h: float, ref, heat) -> None:
        d.qfrc_applied[:] = 0.0
        for i, j in enumerate(self.joints):
            c = self.cols[i]
            tau = j.step(t, h, float(d.qpos[c]), float(d.qvel[c]), j.motor_torque(ref[i], d.qfrc_bias[c]), heat[i])
            j.apply(m, d, c, tau)
            self.last[i] = tau

    def torques(self, d) -> list:
        return list(self.last)

    def timing(self) -> dict:
        return {"fmu_do_step": sum(j.fmu_seconds for j in self.joints),
                "fmpy_get_set": sum(j.call_seconds for j in self.joints)}

    def close(self) -> None:
        for j in self.joints:
            j.close()


def run_arm(m, engine, plan, duration: float, h: float, record_every: int = 10, frame_label=None, renderer=None,
            stop_when=None) -> Record:
    """The arm for `duration` s at step h, its joints driven by `engine(m, d, cols, q0)`: an
    `FmuArm` (co-simulation) or a `PluginArm` (the native plugin). `plan` gives `reference(t)`
    (joint angles) and `heater` (None, or (t, PCL temperatures °C) -> W per joint): a `Plan` or a
    `TouchTask`."""
    m.opt.timestep = h
    d = mujoco.MjData(m)
    cols = [dof(m, j) for j in JOINTS]
    q0 = plan.reference(0.0)
    d.qpos[cols] = q0
    mujoco.mj_forward(m, d)
    joints = engine(m, d, cols, q0)
    rec = Record()
    tip = m.site("tip").id
    heights = [float(d.site_xpos[tip][2])] * 2  # the tip's height after the last two steps
    force, last_contact = 0.0, -math.inf
    engine_s = 0.0
    t_wall = time.perf_counter()
    n_steps = int(round(duration / h))
    try:
        for n in range(n_steps):
            t = n * h
            ref = plan.reference(t)
            heat = plan.heater(t, joints.temperatures_c(d)) if plan.heater else [0.0] * len(JOINTS)
            joints.drive(m, d, t, h, ref, heat)
            e0 = time.perf_counter()
            mujoco.mj_step(m, d)
            engine_s += time.perf_counter() - e0
            if not np.all(np.isfinite(d.qpos)):
                raise CouplingError(f"the arm's state ran away at t = {t:.4f} s (coupling step {h} s)")
            touching = d.ncon > 0 and (f := contact_force(m, d, "tip", "table")) > 0.0
            if touching and force == 0.0:
                if t + h - last_contact > 0.2:  # a new touch, not a bounce of the last one
                    rec.impacts.append({"t": t + h, "approach_speed_m_s": (heights[0] - heights[1]) / h,
                                        "peak_force_n": 0.0, "bounces": 0})
                else:
                    rec.impacts[-1]["bounces"] += 1
            if touching:
                last_contact = t + h
                if t + h - rec.impacts[-1]["t"] <= 0.1:
                    rec.impacts[-1]["peak_force_n"] = max(rec.impacts[-1]["peak_force_n"], f)
            had_contact, force = force > 0.0, (f if touching else 0.0)
            heights = [heights[1], float(d.site_xpos[tip][2])]
            # every step while the tip touches (impacts last a few ms), else every `record_every`
            if n % record_every == 0 or n == n_steps - 1 or touching or had_contact:
                rec.t.append(t + h)
                rec.q.append(d.qpos[cols].copy())
                rec.torque.append(joints.torques(d))
                rec.pcl_c.append(joints.temperatures_c(d))
                rec.stiffness.append(joints.stiffnesses(d))
                rec.contact.append(force)
            label = frame_label(t + h, h) if frame_label is not None else None
            if label and renderer is not None:
                renderer.update_scene(d)
                rec.frames.append((t + h, label, renderer.render().copy()))
            if stop_when is not None and stop_when(t + h):
                break
    finally:
        joints.close()
    total = time.perf_counter() - t_wall
    parts = joints.timing()
    rec.seconds = {
        "simulated": (n + 1) * h,
        "wall": total,
        "engine": engine_s,
        **parts,
        "master": total - engine_s - sum(parts.values()),
        "real_time_factor": (n + 1) * h / total,
    }
    return rec


def run_cosim(m, unzipdir, md, plan, duration: float, h: float, settings: dict, **kw) -> Record:
    """The arm with a ThermoVIA FMU at every joint, co-simulated through fmpy (see `run_arm`)."""
    return run_arm(m, lambda m, d, cols, q0: FmuArm(m, d, cols, q0, unzipdir, md, settings), plan, duration, h, **kw)


# ---------------------------------------------------------------------------------------------
# the same arm with the native plugin (crates/mujoco): no FMU, no fmpy, one mj_step


def plugin_config(s: JointSettings) -> dict:
    """The plugin's config for a joint of these settings: the FMU's parameter names."""
    temp = s.pcl_c + ZERO_C
    return {"initial_pcl_temperature": temp, "initial_housing_temperature": temp,
            "ambient_temperature": ROOM_C + ZERO_C, **s.parameters}


def plugin_transmission(s: JointSettings) -> tuple:
    """(K_eff, C_eff) of the plugin's transmission at the joint's initial temperature, read from a
    one-joint scene after its reset (the same model as the FMU's)."""
    cfg = "".join(f'<config key="{k}" value="{v!r}"/>' for k, v in plugin_config(s).items())
    xml = f"""<mujoco><extension><plugin plugin="thermovia.joint"/></extension>
      <option timestep="1e-4"/><worldbody><body><joint name="j" damping="1e3"/>
      <geom type="sphere" size="0.1" mass="10"/></body></worldbody>
      <actuator><plugin name="j" joint="j" plugin="thermovia.joint">{cfg}</plugin></actuator></mujoco>"""
    m = tj.model_from_xml(xml)
    y = tj.read(m, mujoco.MjData(m), "j")
    return y["effective_stiffness"], y["effective_damping"]


def plugin_arm_xml(xml_path, settings: dict) -> str:
    """arm3.xml with a `thermovia.joint` actuator on every joint (named after it) and a zero-gain heater
    actuator beside it (`<joint>_heater`, 0–50 W). Each joint's damping is its transmission's C_eff at
    its initial temperature, taken implicitly by MuJoCo and given back by the plugin (implicit_damping)."""
    tree = ET.parse(xml_path)
    root = tree.getroot()
    ext = root.find("extension")
    if ext is None:
        ext = ET.Element("extension")
        root.insert(0, ext)
    ET.SubElement(ext, "plugin", {"plugin": tj.PLUGIN})
    actuator = root.find("actuator")
    if actuator is None:
        actuator = ET.SubElement(root, "actuator")
    for name in JOINTS:
        damping = plugin_transmission(settings[name])[1]
        joint = next(e for e in root.iter("joint") if e.get("name") == name)
        joint.set("damping", repr(damping))
        a = ET.SubElement(actuator, "plugin", {"name": name, "joint": name, "plugin": tj.PLUGIN})
        for k, v in {**plugin_config(settings[name]), "heater": f"{name}_heater", "implicit_damping": damping}.items():
            ET.SubElement(a, "config", {"key": k, "value": v if isinstance(v, str) else repr(v)})
        ET.SubElement(actuator, "general", {"name": f"{name}_heater", "joint": name, "gainprm": "0", "biasprm": "0",
                                            "ctrlrange": "0 50", "ctrllimited": "true"})
    return ET.tostring(root, encoding="unicode")


class PluginArm:
    """The arm's joints as `thermovia.joint` actuators: the PD writes each motor torque into ctrl, the
    heater power into the heater actuator's ctrl; the joints' states are read from plugin_state."""

    NAMES = ("motor_angle", "motor_speed", "pcl_temperature", "effective_stiffness", "transmitted_torque_mean")

    def __init__(self, m, d, cols, q0, settings: dict):
        self.cols = np.array(cols)
        self.settings = [settings[j] for j in JOINTS]
        self.kp = np.array([s.kp for s in self.settings])
        self.kd = np.array([s.kd for s in self.settings])
        self.act = np.array([m.actuator(j).id for j in JOINTS])
        self.heat = np.array([m.actuator(f"{j}_heater").id for j in JOINTS])
        self.at = {n: np.array([tj.index(m, j, n) for j in JOINTS]) for n in self.NAMES}
        # each motor starts where the link is in equilibrium, as in the co-simulation
        for i, j in enumerate(JOINTS):
            k = d.plugin_state[self.at["effective_stiffness"][i]]
            tj.set_motor(m, d, j, float(q0[i] + d.qfrc_bias[cols[i]] / k))

    def temperatures_c(self, d) -> list:
        return (d.plugin_state[self.at["pcl_temperature"]] - ZERO_C).tolist()

    def stiffnesses(self, d) -> list:
        return d.plugin_state[self.at["effective_stiffness"]].tolist()

    def drive(self, m, d, t: float, h: float, ref, heat) -> None:
        """`pd_torque` for the three joints at once."""
        ps, at = d.plugin_state, self.at
        d.ctrl[self.act] = pd_torque(self.kp, self.kd, ps[at["motor_angle"]], ps[at["motor_speed"]],
                                     ps[at["effective_stiffness"]], ref, d.qfrc_bias[self.cols])
        d.ctrl[self.heat] = heat

    def torques(self, d) -> list:
        return d.plugin_state[self.at["transmitted_torque_mean"]].tolist()

    def timing(self) -> dict:
        return {}

    def close(self) -> None:
        pass


def load_plugin_arm(xml_path, settings: dict):
    """The plugin's arm model, compiled (the plugin library is loaded first)."""
    try:
        return tj.model_from_xml(plugin_arm_xml(xml_path, settings))
    except ValueError as e:
        raise CouplingError(f"{xml_path} with the thermovia.joint plugin: {e}") from e


def run_plugin(xml_path, plan, duration: float, h: float, settings: dict, **kw) -> Record:
    """The arm with a `thermovia.joint` actuator at every joint (see `run_arm`)."""
    m = load_plugin_arm(xml_path, settings)
    return run_arm(m, lambda m, d, cols, q0: PluginArm(m, d, cols, q0, settings), plan, duration, h, **kw)


# ---------------------------------------------------------------------------------------------
# the same arm simulated monolithically: the transmission as a MuJoCo spring–damper


def monolithic_xml(xml_path, stiffness: dict, damping: dict, j_motor: float, b_motor: float) -> str:
    """arm3.xml with a rotor on each joint (a hinge of armature J_m and damping B_m, beside the
    link on the parent) and a fixed tendon θm − q of stiffness K_eff and damping C_eff between them."""
    tree = ET.parse(xml_path)
    root = tree.getroot()
    parent_of = {c: p for p in root.iter() for c in p}
    tendon = root.find("tendon")
    if tendon is None:
        tendon = ET.SubElement(root, "tendon")
    for name in JOINTS:
        joint = next(e for e in root.iter("joint") if e.get("name") == name)
        link = parent_of[joint]
        parent = parent_of[link]
        rotor = ET.SubElement(parent, "body", {"name": f"rotor_{name}", "pos": link.get("pos", "0 0 0")})
        ET.SubElement(rotor, "inertial", {"pos": "0 0 0", "mass": "1e-6", "diaginertia": "1e-10 1e-10 1e-10"})
        ET.SubElement(
            rotor,
            "joint",
            {"name": f"rotor_{name}", "type": "hinge", "axis": joint.get("axis"), "armature": repr(j_motor),
             "damping": repr(b_motor)},
        )
        fixed = ET.SubElement(
            tendon, "fixed", {"name": f"transmission_{name}", "stiffness": repr(stiffness[name]),
                              "damping": repr(damping[name])}
        )
        ET.SubElement(fixed, "joint", {"joint": f"rotor_{name}", "coef": "1"})
        ET.SubElement(fixed, "joint", {"joint": name, "coef": "-1"})
    return ET.tostring(root, encoding="unicode")


def run_monolithic(xml: str, plan: Plan, duration: float, h: float, settings: dict, record_every: int,
                   rk4: bool = False) -> Record:
    """The monolithic arm: the same PD on the rotor angle, sampled every h, the same feed-forward;
    MuJoCo's implicitfast integrator as in the co-simulation, or RK4 for the reference."""
    m = mujoco.MjModel.from_xml_string(xml)
    m.opt.timestep = h
    if rk4:
        m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    d = mujoco.MjData(m)
    links = [dof(m, j) for j in JOINTS]
    rotors = [dof(m, f"rotor_{j}") for j in JOINTS]
    q0 = plan.reference(0.0)
    d.qpos[[int(m.joint(j).qposadr[0]) for j in JOINTS]] = q0
    m.tendon_lengthspring[:] = 0.0
    mujoco.mj_forward(m, d)
    # each rotor where the link is in equilibrium (as in the co-simulation)
    for i, name in enumerate(JOINTS):
        k = m.tendon_stiffness[m.tendon(f"transmission_{name}").id]
        d.qpos[m.joint(f"rotor_{name}").qposadr[0]] = q0[i] + d.qfrc_bias[links[i]] / k
    mujoco.mj_forward(m, d)
    rec = Record()
    n_steps = int(round(duration / h))
    for n in range(n_steps):
        t = n * h
        ref = plan.reference(t)
        for i, name in enumerate(JOINTS):
            s = settings[name]
            ff = d.qfrc_bias[links[i]]
            target = ref[i] + ff / m.tendon_stiffness[m.tendon(f"transmission_{name}").id]
            d.qfrc_applied[rotors[i]] = (
                s.kp * (target - d.qpos[m.joint(f"rotor_{name}").qposadr[0]]) - s.kd * d.qvel[rotors[i]] + ff
            )
        mujoco.mj_step(m, d)
        if n % record_every == 0 or n == n_steps - 1:
            rec.t.append(t + h)
            rec.q.append(np.array([d.qpos[m.joint(j).qposadr[0]] for j in JOINTS]))
            rec.contact.append(contact_force(m, d, "tip", "table"))
    return rec


def _at(rec: Record, times) -> np.ndarray:
    t = np.array(rec.t)
    q = np.array(rec.q)
    return np.stack([np.interp(times, t, q[:, i]) for i in range(q.shape[1])], axis=1)


def accuracy_study(xml_path, unzipdir, md, plan, duration, settings, steps=(0.5e-3, 1e-3, 2e-3, 4e-3)) -> dict:
    """Co-simulation against the monolithic arm (RK4 at 0.1 ms), cold (the transmission linear at
    its K_eff, C_eff): the largest joint-angle error and the contact force at the end of the press,
    for each coupling step; and the monolithic arm at the same step with the co-simulation's
    integrator, for the engine's own share of the error."""
    k, c, jm, bm = transmission_at(unzipdir, md, ROOM_C)
    xml = monolithic_xml(xml_path, {j: k for j in JOINTS}, {j: c for j in JOINTS}, jm, bm)
    ref_h = 1e-4
    ref = run_monolithic(xml, plan, duration, ref_h, settings, record_every=1, rk4=True)
    times = np.arange(0.05, duration, 0.005)
    qref = _at(ref, times)
    rows = []
    for h in steps:
        m = load_arm(xml_path)
        co = run_cosim(m, unzipdir, md, plan, duration, h, settings, record_every=1)
        native = run_plugin(xml_path, plan, duration, h, settings, record_every=1)
        mono = run_monolithic(xml, plan, duration, h, settings, record_every=1)
        rows.append({
            "step_s": h,
            "coupling_max_angle_error_rad": float(np.max(np.abs(_at(co, times) - _at(mono, times)))),
            "cosim_max_angle_error_rad": float(np.max(np.abs(_at(co, times) - qref))),
            "plugin_max_angle_error_rad": float(np.max(np.abs(_at(native, times) - qref))),
            "plugin_vs_cosim_max_angle_error_rad": float(np.max(np.abs(_at(native, times) - _at(co, times)))),
            "plugin_contact_force_n": float(np.interp(duration - 0.05, native.t, native.contact)),
            "monolithic_same_step_max_angle_error_rad": float(np.max(np.abs(_at(mono, times) - qref))),
            "cosim_contact_force_n": float(np.interp(duration - 0.05, co.t, co.contact)),
            "reference_contact_force_n": float(np.interp(duration - 0.05, ref.t, ref.contact)),
        })
    return {"reference_step_s": ref_h, "stiffness": k, "damping": c, "rows": rows}


# ---------------------------------------------------------------------------------------------
# cross-check: `thermovia arm`'s planar two-link arm through this MuJoCo path


def two_link_bodies(cfg: dict) -> tuple:
    """(mass, centre-of-mass distance from its joint, inertia about the centre) of `thermovia arm`'s
    two bodies (crates/tools/src/arm/dynamics.rs, `body1`/`body2`): a uniform rod, a point mass at
    its end (the elbow actuator; the payload), the hub."""

    def body(m_rod, l, m_end):
        m = m_rod + m_end
        lc = (m_rod * 0.5 * l + m_end * l) / m
        i = m_rod * l * l / 12.0 + m_rod * (0.5 * l - lc) ** 2 + m_end * (l - lc) ** 2 + cfg["hub_inertia"]
        return m, lc, i

    return body(cfg["m1"], cfg["l1"], cfg["elbow_mass"]), body(cfg["m2"], cfg["l2"], cfg["payload_mass"])


def two_link_xml(cfg: dict) -> str:
    """`thermovia arm`'s arm in MJCF: two bodies in the x–z plane, gravity along −z, each with the
    mass, centre of mass and inertia `two_link_bodies` gives it, and a tip site."""
    (m1, lc1, i1), (m2, lc2, i2) = two_link_bodies(cfg)
    return f"""<mujoco model="thermovia_arm2">
  <compiler angle="radian"/>
  <option gravity="0 0 {-cfg['gravity']}" integrator="implicitfast"/>
  <worldbody>
    <body name="link1">
      <joint name="shoulder" type="hinge" axis="0 -1 0"/>
      <inertial pos="{lc1} 0 0" mass="{m1}" diaginertia="{i1} {i1} {i1}"/>
      <geom type="capsule" fromto="0 0 0 {cfg['l1']} 0 0" size="0.01" contype="0" conaffinity="0" mass="0"/>
      <body name="link2" pos="{cfg['l1']} 0 0">
        <joint name="elbow" type="hinge" axis="0 -1 0"/>
        <inertial pos="{lc2} 0 0" mass="{m2}" diaginertia="{i2} {i2} {i2}"/>
        <geom type="capsule" fromto="0 0 0 {cfg['l2']} 0 0" size="0.01" contype="0" conaffinity="0" mass="0"/>
        <site name="tip" pos="{cfg['l2']} 0 0"/>
      </body>
    </body>
  </worldbody>
</mujoco>"""


def two_link_run(cfg: dict, unzipdir, md, h: float, temps_c, holding_w) -> dict:
    """The `thermovia arm` task (minimum-jerk move of the tip into its compliant wall, the same PD on
    the motor angle with gravity fed forward and the motor set-point ahead by g/K) with its joints
    as link-driven FMUs in MuJoCo: the task metrics that `thermovia arm` reports."""
    m = mujoco.MjModel.from_xml_string(two_link_xml(cfg))
    m.opt.timestep = h
    d = mujoco.MjData(m)
    names = ("shoulder", "elbow")
    l1, l2, g0 = cfg["l1"], cfg["l2"], cfg["gravity"]
    (mA, lcA, _), (mB, lcB, _) = two_link_bodies(cfg)

    def gravity(q):
        c12 = math.cos(q[0] + q[1])
        return np.array([g0 * ((mA * lcA + mB * l1) * math.cos(q[0]) + mB * lcB * c12), g0 * mB * lcB * c12])

    def ik(p):
        c2 = (p[0] ** 2 + p[1] ** 2 - l1 * l1 - l2 * l2) / (2 * l1 * l2)
        q2 = -math.atan2(math.sqrt(1 - c2 * c2), c2)
        return np.array([math.atan2(p[1], p[0]) - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2)), q2])

    a, b = ik(cfg["start_tip"]), ik(cfg["goal_tip"])

    def plan(t):
        s = min(max((t - cfg["move_start"]) / cfg["move_duration"], 0.0), 1.0)
        pos = s ** 3 * (10 - 15 * s + 6 * s * s)
        vel = 0.0 if s <= 0 or s >= 1 else 30 * s * s * (1 - s) ** 2 / cfg["move_duration"]
        return a + (b - a) * pos, (b - a) * vel

    d.qpos[:] = a
    mujoco.mj_forward(m, d)
    ks = [transmission_at(unzipdir, md, t)[0] for t in temps_c]
    g = gravity(a)
    settings = [JointSettings(kp=cfg["kp"], kd=cfg["kd"], pcl_c=temps_c[i],
                              parameters={"motor_inertia": cfg["motor_inertia"], "motor_damping": cfg["motor_damping"],
                                          "excitation_frequency": cfg["excitation_frequency"]}) for i in range(2)]
    joints = [FmuJoint(unzipdir, md, n, settings[i], float(a[i]), motor0=float(a[i] + g[i] / ks[i])) for i, n in enumerate(names)]
    site = m.site("tip").id
    t_rec, force, tip = [], [], []
    try:
        for n in range(int(round(cfg["duration"] / h))):
            t = n * h
            qs, qsd = plan(t)
            gs = gravity(qs)
            d.qfrc_applied[:] = 0.0
            for i, j in enumerate(joints):
                y = j.y
                tm_ = cfg["kp"] * (qs[i] + gs[i] / y["effective_stiffness"] - y["motor_angle"]) + cfg["kd"] * (qsd[i] - y["motor_speed"]) + gs[i]
                tau = j.step(t, h, float(d.qpos[i]), float(d.qvel[i]), tm_, holding_w[i])
                j.apply(m, d, i, tau)
            # the compliant wall at x = wall_x pushes the tip back (never pulls)
            x = d.site_xpos[site][0]
            jp = np.zeros((3, m.nv))
            mujoco.mj_jacSite(m, d, jp, None, site)
            vx = float(jp[0] @ d.qvel)
            fx = -max(cfg["wall_stiffness"] * (x - cfg["wall_x"]) + cfg["wall_damping"] * vx, 0.0) if x > cfg["wall_x"] else 0.0
            d.qfrc_applied[:] += jp[0] * fx
            mujoco.mj_step(m, d)
            t_rec.append(t + h)
            force.append(-fx)
            tip.append(d.site_xpos[site][[0, 2]].copy())
    finally:
        for j in joints:
            j.close()
    force = np.array(force)
    touching = np.nonzero(force > 0)[0]
    k = int(np.argmax(force))
    return {
        "first_contact_s": t_rec[touching[0]] if len(touching) else None,
        "peak_contact_force_n": float(force[k]),
        "peak_contact_force_time_s": t_rec[k],
        "final_contact_force_n": float(force[-1]),
        "final_tip_m": tip[-1].tolist(),
    }


def two_link_crosscheck(arm_report: dict, unzipdir, md, h: float = 1e-3) -> dict:
    """`thermovia arm`'s two tasks (cold, hot) through the MuJoCo path, against its own report."""
    cfg = arm_report["config"]
    rows = []
    for task in arm_report["tasks"]:
        temps = task["scenario"]["pcl_temperature_c"]
        ours = two_link_run(cfg, unzipdir, md, h, temps, [j["holding_power"] for j in task["joints"]])
        acc = next(a for a in arm_report["accuracy"] if a["scenario"] == task["scenario"]["name"] and abs(a["step_s"] - h) < 1e-12)
        rows.append({
            "scenario": task["scenario"]["name"],
            "mujoco": ours,
            "thermovia_arm": {k: task[k] for k in ("first_contact_s", "peak_contact_force_n", "final_contact_force_n")},
            "thermovia_arm_coupling_error": {"peak_force_error_n": acc["peak_force_error_n"], "tip_error_m": acc["tip_error_m"]},
        })
    return {"step_s": h, "rows": rows}


# ---------------------------------------------------------------------------------------------
# rendering, plots, report


def make_renderer(m, width=480, height=360):
    """An off-screen renderer, or (None, why) when the backend is missing: the simulation goes on."""
    if GL_PROBLEM:
        return None, GL_PROBLEM
    try:
        return mujoco.Renderer(m, height, width), None
    except Exception as e:  # noqa: BLE001 - any backend failure only skips the frames
        return None, f"off-screen rendering unavailable (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {e}"


def write_frames(out: pathlib.Path, frames) -> list:
    from PIL import Image, ImageDraw

    names = []
    images = []
    from PIL import ImageFont

    font = ImageFont.load_default(size=20)
    for t, label, rgb in frames:
        img = Image.fromarray(rgb)
        draw = ImageDraw.Draw(img)
        text = f"{label}   t = {t:.2f} s"
        box = draw.textbbox((10, 10), text, font=font)
        # on a white box: the sky behind the top left corner is black
        draw.rectangle((box[0] - 6, box[1] - 4, box[2] + 6, box[3] + 4), fill=(255, 255, 255))
        draw.text((10, 10), text, fill=(0, 0, 0), font=font)
        images.append(img)
    if images:
        w, h = images[0].size
        strip = Image.new("RGB", (w * len(images), h), "white")
        for i, img in enumerate(images):
            strip.paste(img, (i * w, 0))
        strip.save(out / "frames.png")
        names.append("frames.png")
        images[0].save(out / "animation.gif", save_all=True, append_images=images[1:], duration=600, loop=0)
        names.append("animation.gif")
    return names


def plot_run(out: pathlib.Path, rec: Record, touches: list, heat_on: float) -> str:
    """The two touches side by side at full resolution (contact force, joint torques), then the heating
    over the whole run (PCL temperatures, K_eff). Legends sit outside the axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = rec.arrays()
    t = a["t"]
    colours = ("#0072B2", "#E69F00", "#009E73")  # colour-blind safe
    styles = ("-", "--", "-.")
    fig = plt.figure(figsize=(10, 9))
    grid = fig.add_gridspec(4, 2, height_ratios=[1, 1, 1, 1], hspace=0.5, wspace=0.25, top=0.88)
    names = ("touch, cold", "touch, elbow at its target temperature")
    force_axes, torque_axes = [], []
    for col, ((start, end), name) in enumerate(zip(touches, names)):
        sel = (t >= start - 0.6) & (t <= end + 0.5)
        ax = fig.add_subplot(grid[0, col])
        ax.plot(t[sel] - start, a["contact"][sel], color="k", lw=1.2)
        for hit in rec.impacts:
            if start - 0.6 <= hit["t"] <= end + 0.5:
                ax.annotate(f"impact {hit['peak_force_n']:.0f} N\nat {hit['approach_speed_m_s'] * 1e3:.0f} mm/s",
                            (hit["t"] - start, hit["peak_force_n"]), textcoords="offset points", xytext=(12, -18),
                            fontsize=8)
        hold = (t >= end - 0.3) & (t <= end)
        press = float(np.mean(a["contact"][hold]))
        ax.annotate(f"steady press {press:.2f} N", ((start + end) / 2 - start, press), textcoords="offset points",
                    xytext=(0, 14), ha="center", fontsize=8)
        ax.set_title(name, fontsize=10)
        ax.set_ylabel("contact force (N)")
        ax.grid(alpha=0.3)
        force_axes.append(ax)
        ax2 = fig.add_subplot(grid[1, col], sharex=ax)
        for i, j in enumerate(JOINTS):
            ax2.plot(t[sel] - start, a["torque"][sel, i], color=colours[i], ls=styles[i], label=j)
        ax2.set_ylabel("joint torque (N·m)")
        torque_axes.append(ax2)
        ax2.set_xlabel("time from reaching the press posture (s)")
        ax2.grid(alpha=0.3)
    lo, hi = min(ax.get_ylim()[0] for ax in torque_axes), max(ax.get_ylim()[1] for ax in torque_axes)
    for ax in torque_axes:
        ax.set_ylim(lo, hi)
    top = max(ax.get_ylim()[1] for ax in force_axes)
    for ax in force_axes:
        ax.set_ylim(-0.05 * top, 1.15 * top)
    handles, labels = ax2.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, bbox_to_anchor=(0.5, 0.905), frameon=False,
               title="joints")
    for row, (key, label) in enumerate((("pcl_c", "PCL temperature (°C)"), ("stiffness", "K_eff (N·m/rad)"))):
        ax = fig.add_subplot(grid[2 + row, :])
        for i, j in enumerate(JOINTS):
            ax.plot(t, a[key][:, i], color=colours[i], ls=styles[i], label=j)
        events = ((touches[0][0], "touch, cold"), (heat_on, "heater on"), (touches[1][0], "touch, hot"))
        for k, (x, what) in enumerate(events):
            ax.axvline(x, color="0.6", lw=0.8)
            if row == 0:  # staggered, so labels of close events do not overlap
                ax.annotate(what, (x, 1.0), xycoords=("data", "axes fraction"), xytext=(3, -12 - 12 * (k % 2)),
                            textcoords="offset points", fontsize=8, color="0.3")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if row == 1:
            ax.set_xlabel("time (s)")
    fig.savefig(out / "run.png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return "run.png"


def plot_accuracy(out: pathlib.Path, study: dict) -> str:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = study["rows"]
    h = [r["step_s"] * 1e3 for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.loglog(h, [r["cosim_max_angle_error_rad"] for r in rows], "o-", label="co-simulation (FMU joints)")
    ax.loglog(h, [r["plugin_max_angle_error_rad"] for r in rows], "x", ms=10, mew=2, label="plugin (thermovia.joint)")
    ax.loglog(h, [r["monolithic_same_step_max_angle_error_rad"] for r in rows], "s--", label="monolithic, same step")
    ax.set_xticks(h, [f"{x:g}" for x in h])  # the steps themselves, not 6×10⁻¹ and 2×10⁰
    ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    ax.set_xlabel("coupling step (ms)")
    ax.set_ylabel("largest joint-angle error (rad)")
    ax.set_title(f"against the monolithic arm at {study['reference_step_s'] * 1e3:g} ms")
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "accuracy.png", dpi=90)
    plt.close(fig)
    return "accuracy.png"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="""The task: move above the table, touch it (cold), lift, heat the elbow's PCL to the target
with its heater, touch again (soft). Report: out/report.md, report.json, run.png (joint torques,
contact force, PCL temperatures, K_eff), accuracy.png (error against the coupling step), frames.png
and animation.gif (off-screen frames; skipped with a message when no rendering backend works).

Examples:
  python examples/mujoco/thermovia_mujoco.py --out out/mujoco
  python examples/mujoco/thermovia_mujoco.py --out /tmp/m --step 2e-3 --no-accuracy
  MUJOCO_GL=egl python examples/mujoco/thermovia_mujoco.py --out /tmp/m""",
    )
    ap.add_argument("--out", required=True, type=pathlib.Path, help="report folder (replaced when the run succeeds)")
    ap.add_argument("--fmu", type=pathlib.Path, default=DEFAULT_FMU, help="the packaged FMU [%(default)s]")
    ap.add_argument("--model", type=pathlib.Path, default=DEFAULT_MODEL, help="MJCF with hinges %s [%%(default)s]" % ", ".join(JOINTS))
    ap.add_argument("--step", type=float, default=1e-3, help="coupling step = MuJoCo step, s [%(default)s]")
    ap.add_argument("--engine", choices=("plugin", "fmu"), default="plugin",
                    help="the joints as the native plugin (thermovia.joint) or as FMUs through fmpy [%(default)s]")
    ap.add_argument("--heater-power", type=float, default=10.0, help="elbow heater power, W [%(default)s]")
    ap.add_argument("--soft-c", type=float, default=60.0, help="PCL temperature the elbow is heated to, °C [%(default)s]")
    ap.add_argument("--max-seconds", type=float, default=600.0, help="longest simulated time to wait for the heating, s [%(default)s]")
    ap.add_argument("--no-accuracy", action="store_true", help="skip the comparison with the monolithic arm")
    ap.add_argument("--no-frames", action="store_true", help="skip the off-screen frames")
    ap.add_argument("--thermovia", type=pathlib.Path, default=ROOT / "target" / "release" / "thermovia",
                    help="the thermovia binary, for the cross-check with `thermovia arm` [%(default)s]; skipped when absent")
    args = ap.parse_args(argv)
    try:
        report = run_example(args)
    except CouplingError as e:
        print(f"thermovia_mujoco: {e}", file=sys.stderr)
        return 2
    print(report)
    return 0


class TouchTask:
    """Move above the table, touch it cold, lift; heat the elbow to `soft_c`; once it is there,
    touch again with the same motor references. One continuous run: the second touch starts when
    the elbow's PCL reaches the target (`heated_at`, set by the master as it happens)."""

    def __init__(self, p: dict, heater_power: float, soft_c: float, first_start: float = 0.6):
        self.p = p
        self.first = touch_plan(p, first_start)
        self.cold = Plan([(0.0, p["home"]), *self.first])
        self.heat_on = self.first[-1][0] + 0.2
        self.power = heater_power
        self.soft_c = soft_c
        self.heated_at = None
        self.second = None

    def reference(self, t: float) -> np.ndarray:
        return self.cold.reference(t) if self.second is None else self.second.reference(t)

    def heater(self, t: float, temps) -> list:
        w = [0.0] * len(JOINTS)
        elbow = JOINTS.index("elbow")
        if t >= self.heat_on and self.heated_at is None and temps[elbow] >= self.soft_c:
            self.heated_at = t
            self.second = Plan([(0.0, self.p["above"]), *touch_plan(self.p, t + 0.2)])
        # a thermostat: on below the target (heating, then holding it)
        if t >= self.heat_on and temps[elbow] < self.soft_c:
            w[elbow] = self.power
        return w

    def touches(self) -> list:
        """(start of the hold at the press, end of it) of the touches so far."""
        out = [(self.first[1][0], self.first[2][0])]
        if self.second is not None:
            out.append((self.second.waypoints[2][0], self.second.waypoints[3][0]))
        return out

    def done(self, t: float) -> bool:
        return self.second is not None and t >= self.second.waypoints[-1][0] + 0.4

    def frame_label(self, t: float, h: float):
        marks = [(0.0, "home"), (self.first[2][0], "touch, cold")]
        if self.second is not None:
            marks += [(self.heated_at, "heated"), (self.second.waypoints[3][0], "touch, soft")]
        return next((label for at, label in marks if at <= t < at + h), None)


def run_example(args) -> str:
    m = load_arm(args.model)
    unzipdir, md = open_fmu(args.fmu)
    settings = {j: JointSettings() for j in JOINTS}
    stability = check_step(m, unzipdir, md, args.step, settings)
    p = postures(m)
    task = TouchTask(p, args.heater_power, args.soft_c)
    if args.engine == "plugin":
        m_run = load_plugin_arm(args.model, settings)

        def engine(m, d, cols, q0):
            return PluginArm(m, d, cols, q0, settings)
    else:
        m_run = m

        def engine(m, d, cols, q0):
            return FmuArm(m, d, cols, q0, unzipdir, md, settings)
    renderer, why = (None, "frames not asked for (--no-frames)") if args.no_frames else make_renderer(m_run)
    rec = run_arm(m_run, engine, task, args.max_seconds, args.step, record_every=20,
                  frame_label=task.frame_label, renderer=renderer, stop_when=task.done)
    if task.heated_at is None:
        raise CouplingError(f"the elbow did not reach {args.soft_c} °C within {args.max_seconds} s at {args.heater_power} W")
    t = np.array(rec.t)

    def during(values, span):
        # the last 0.3 s of a touch's hold: the steady press
        sel = (t >= span[1] - 0.3) & (t <= span[1])
        return np.mean(np.array(values)[sel], axis=0)

    (cold_span, soft_span) = task.touches()
    cold_force, soft_force = float(during(rec.contact, cold_span)), float(during(rec.contact, soft_span))
    cold_k, soft_k = during(rec.stiffness, cold_span).tolist(), during(rec.stiffness, soft_span).tolist()
    study = None
    if not args.no_accuracy:
        cold_plan = Plan([(0.0, p["home"]), *task.first[:3]])
        study = accuracy_study(args.model, unzipdir, md, cold_plan, task.first[2][0], settings)

    cross = None
    if args.thermovia.exists():
        with tempfile.TemporaryDirectory() as arm_dir:
            import subprocess

            run = subprocess.run([str(args.thermovia), "arm", "--out", arm_dir, "--step", str(args.step)],
                                 capture_output=True, text=True)
            if run.returncode != 0:
                raise CouplingError(f"`thermovia arm` failed: {run.stderr.strip()}")
            cross = two_link_crosscheck(json.loads((pathlib.Path(arm_dir) / "report.json").read_text()), unzipdir, md, args.step)

    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = pathlib.Path(tempfile.mkdtemp(prefix=".mujoco-", dir=args.out.parent))
    files = [plot_run(tmp, rec, [cold_span, soft_span], task.heat_on)]
    if study:
        files.append(plot_accuracy(tmp, study))
    frame_note = why
    if renderer is not None:
        files += write_frames(tmp, rec.frames)
        frame_note = f"{len(rec.frames)} frames rendered off-screen (MUJOCO_GL={os.environ.get('MUJOCO_GL')})"
    report = {
        "step_s": args.step,
        "engine": args.engine,
        "stability": stability,
        "contact_force_n": {"cold": cold_force, "soft": soft_force, "ratio": soft_force / cold_force if cold_force else None},
        "elbow_heated_c": args.soft_c,
        "heater_power_w": args.heater_power,
        "heating_seconds": task.heated_at - task.heat_on,
        "stiffness_at_touch": {"cold": cold_k, "soft": soft_k},
        "impacts": rec.impacts,
        "pcl_temperature_c_at_touch": {"cold": during(rec.pcl_c, cold_span).tolist(), "soft": during(rec.pcl_c, soft_span).tolist()},
        "accuracy": study,
        "two_link_crosscheck": cross if cross else f"skipped: no thermovia binary at {args.thermovia}",
        "timing": rec.seconds,
        "frames": frame_note,
        "files": files,
    }
    (tmp / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    (tmp / "report.md").write_text(markdown(report))
    if args.out.exists():
        shutil.rmtree(args.out)
    tmp.rename(args.out)
    return f"thermovia_mujoco: wrote {args.out}/report.md ({', '.join(files)}); contact force cold {cold_force:.2f} N, soft {soft_force:.2f} N"


def impacts_text(impacts: list) -> str:
    """Why the impact peaks look as they do: they are set before the transmission can yield."""
    if len(impacts) < 2:
        return ""
    a, b = impacts[0], impacts[-1]
    return (
        f"Each touch starts with an impact: {a['peak_force_n']:.1f} N cold and {b['peak_force_n']:.1f} N hot, the tip "
        f"arriving at {a['approach_speed_m_s'] * 1e3:.0f} and {b['approach_speed_m_s'] * 1e3:.0f} mm/s. An impact lasts "
        "a few milliseconds and is set by the approach speed, the arm's inertia and MuJoCo's contact softness, before "
        "any transmission can yield, so heating the elbow hardly changes it; the tip then bounces "
        f"({a['bounces']} and {b['bounces']} re-contacts) and settles to the steady press, where the softened elbow "
        "shows. Contact forces are recorded at every step while the tip touches, so the peaks are the simulation's "
        "own.\n\n"
    )


def markdown(r: dict) -> str:
    s = ["# ThermoVIA joints in MuJoCo\n"]
    s.append(
        "Three-joint arm (`examples/mujoco/arm3.xml`), "
        + ("a `thermovia.joint` actuator (the native plugin) at every joint"
           if r["engine"] == "plugin" else "a ThermoVIA FMU in link-driven mode at every joint, through fmpy")
        + f", step {r['step_s'] * 1e3:g} ms (the co-simulation's stability limit {r['stability']['limit_s'] * 1e3:.3g} ms, "
        f"set by {r['stability']['limiting']}).\n"
    )
    c = r["contact_force_n"]
    s.append("## The task\n")
    s.append(
        f"Touch the table cold, lift, heat the elbow's PCL to {r['elbow_heated_c']:g} °C "
        f"({r['heating_seconds']:.1f} s of heating), touch again with the same motor references.\n\n"
        f"| | contact force (N) | elbow K_eff (N·m/rad) |\n|---|---|---|\n"
        f"| cold | {c['cold']:.3f} | {r['stiffness_at_touch']['cold'][2]:.3f} |\n"
        f"| soft | {c['soft']:.3f} | {r['stiffness_at_touch']['soft'][2]:.3f} |\n\n"
        f"The softened elbow presses with {100 * (c['ratio'] or 0):.0f} % of the cold force.\n\n"
        + impacts_text(r["impacts"]) +
        f"![run](run.png)\n"
    )
    if "frames.png" in r["files"]:
        s.append("![frames](frames.png)\n\nAnimation: `animation.gif`.\n")
    else:
        s.append(f"Frames: {r['frames']}.\n")
    if r["accuracy"]:
        a = r["accuracy"]
        s.append("## Accuracy against the monolithic arm\n")
        s.append(
            f"The same arm in MuJoCo alone, each transmission a fixed tendon between a rotor and the link at the FMU's "
            f"cold K_eff = {a['stiffness']:.3f} N·m/rad and C_eff = {a['damping']:.3f} N·m·s/rad, at "
            f"{a['reference_step_s'] * 1e3:g} ms with RK4, is the reference (move and press, cold). The third column is "
            "MuJoCo's own step error (the same sampled controller and integrator, no co-simulation); the fourth isolates "
            "the coupling.\n\n"
            "The plugin runs the co-simulation's coupling inside mj_step; cold, with its implicit damping equal to "
            "C_eff, it is the co-simulation to the bit (last but one column).\n\n"
            "| coupling step (ms) | co-simulation: largest joint-angle error (rad) | plugin: largest joint-angle error (rad) | monolithic at the same step (rad) | co-simulation against the monolithic at the same step (rad) | plugin against co-simulation (rad) | contact force co-sim / plugin / reference (N) |\n|---|---|---|---|---|---|---|\n"
        )
        for row in a["rows"]:
            s[-1] += (
                f"| {row['step_s'] * 1e3:g} | {row['cosim_max_angle_error_rad']:.2e} | {row['plugin_max_angle_error_rad']:.2e} | "
                f"{row['monolithic_same_step_max_angle_error_rad']:.2e} | {row['coupling_max_angle_error_rad']:.2e} | "
                f"{row['plugin_vs_cosim_max_angle_error_rad']:.1e} | {row['cosim_contact_force_n']:.3f} / "
                f"{row['plugin_contact_force_n']:.3f} / {row['reference_contact_force_n']:.3f} |\n"
            )
        s.append("\n![accuracy](accuracy.png)\n")
    x = r["two_link_crosscheck"]
    s.append("## Cross-check with `thermovia arm`\n")
    if isinstance(x, dict):
        s.append(
            "`thermovia arm`'s planar two-link arm (its config, its task, its controller and wall) with its two joints as "
            "link-driven FMUs in MuJoCo, against `thermovia arm`'s own co-simulation (where the FMUs integrate the links "
            f"with an effective inertia and the master the arm), both at {x['step_s'] * 1e3:g} ms. The accuracy the coupling "
            "allows is `thermovia arm`'s own error against its monolithic reference at that step (last column).\n\n"
            "| scenario | peak contact force (N): MuJoCo / thermovia arm | final force (N) | first contact (s) | thermovia arm's own peak-force error (N) |\n|---|---|---|---|---|\n"
        )
        for row in x["rows"]:
            mj, ta = row["mujoco"], row["thermovia_arm"]
            s[-1] += (
                f"| {row['scenario']} | {mj['peak_contact_force_n']:.2f} / {ta['peak_contact_force_n']:.2f} | "
                f"{mj['final_contact_force_n']:.3f} / {ta['final_contact_force_n']:.3f} | {mj['first_contact_s']:.3f} / "
                f"{ta['first_contact_s']:.3f} | {row['thermovia_arm_coupling_error']['peak_force_error_n']:.2f} |\n"
            )
    else:
        s.append(f"{x}.\n")
    t = r["timing"]
    s.append("## Speed\n")
    if r["engine"] == "fmu":
        s.append(
            f"Real-time factor {t['real_time_factor']:.2f} at {r['step_s'] * 1e3:g} ms ({t['simulated']:.1f} s simulated in "
            f"{t['wall']:.1f} s) through the FMU co-simulation. Where the time goes: MuJoCo {100 * t['engine'] / t['wall']:.0f} %, "
            f"the FMUs' fmi2DoStep {100 * t['fmu_do_step'] / t['wall']:.0f} %, fmpy's get/set calls "
            f"{100 * t['fmpy_get_set'] / t['wall']:.0f} %, the Python master {100 * t['master'] / t['wall']:.0f} %.\n"
        )
    else:
        s.append(
            f"Real-time factor {t['real_time_factor']:.2f} at {r['step_s'] * 1e3:g} ms ({t['simulated']:.1f} s simulated in "
            f"{t['wall']:.1f} s) through the `thermovia.joint` plugin. Where the time goes: mj_step with the three joints "
            f"inside it {100 * t['engine'] / t['wall']:.0f} %, the Python loop (controller, heater, recording) "
            f"{100 * t['master'] / t['wall']:.0f} %. `examples/mujoco/bench_plugin.py` measures the plugin against the "
            "co-simulation, under `mujoco.rollout` and per joint.\n"
        )
    return "\n".join(s)


if __name__ == "__main__":
    sys.exit(main())
