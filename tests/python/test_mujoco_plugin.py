"""The native MuJoCo actuator plugin `thermovia.joint` (crates/mujoco): loading and refusals, state in
MuJoCo's hands (reset, keyframes, mj_copyData, rollout on two threads), and the same physics as the
FMU co-simulation on the three-joint arm."""
import copy
import os
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "osmesa")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "examples" / "mujoco"))
sys.path.insert(0, str(ROOT / "crates" / "mujoco" / "python"))
import mujoco  # noqa: E402
import thermovia_joint as tj  # noqa: E402
import thermovia_mujoco as tm  # noqa: E402

tj.load_plugin()

SCENE = """
<mujoco>
  <extension><plugin plugin="thermovia.joint"/></extension>
  <option timestep="{h}" integrator="{integrator}"/>
  <worldbody>
    <body name="link">
      <joint name="hinge" type="hinge" axis="0 -1 0" damping="{damping}"/>
      <geom type="capsule" fromto="0 0 0 0.14 0 0" size="0.01" mass="0.91"/>
    </body>
  </worldbody>
  <actuator>
    <plugin name="joint" joint="hinge" plugin="thermovia.joint" ctrlrange="-2 2" ctrllimited="true">
      <config key="heater" value="heater"/>
      <config key="implicit_damping" value="{damping}"/>
      {config}
    </plugin>
    <general name="heater" joint="hinge" gainprm="0" biasprm="0" ctrlrange="0 20" ctrllimited="true"/>
  </actuator>
  <keyframe><key name="raised" qpos="0.7" qvel="0.3" ctrl="0.4 5"/></keyframe>
</mujoco>"""


def scene(h=1e-3, integrator="implicitfast", damping=16.0, config=""):
    return SCENE.format(h=h, integrator=integrator, damping=damping, config=config)


def refused(xml: str) -> str:
    with pytest.raises(ValueError) as e:
        tj.model_from_xml(xml)
    return str(e.value)


def test_bad_config_is_refused_with_the_variable_named():
    assert "pcl_mass = -1 is below its minimum" in refused(scene(config='<config key="pcl_mass" value="-1"/>'))
    assert 'pcl_mass = "heavy" is not a number' in refused(scene(config='<config key="pcl_mass" value="heavy"/>'))
    why = refused(scene(config='<config key="link_inertia" value="0.1"/>'))
    assert "link_inertia is not a config key" in why and "MuJoCo" in why
    assert "did you mean 'pcl_mass'" in refused(scene(config='<config key="pcl_mas" value="0.01"/>'))
    assert "link_drive = 1" in refused(scene(config='<config key="link_drive" value="integrated"/>'))
    assert "integrator" in refused(scene(integrator="RK4"))
    # the same joint without its damping taken implicitly: 1 ms is past the coupling's limit
    why = refused(scene(damping=0.0))
    assert "stability limit" in why and "implicit_damping" in why
    assert "names no actuator" in refused(scene().replace('value="heater"', 'value="heatr"'))
    # a good config goes through, enumerations by name too
    m = tj.model_from_xml(scene(config='<config key="viscoelastic_law" value="prony"/>'))
    assert m.nplugin == 1


def test_euler_and_implicit_integrators_run():
    for integrator in ("Euler", "implicit", "implicitfast"):
        m = tj.model_from_xml(scene(integrator=integrator))
        d = mujoco.MjData(m)
        d.ctrl[:] = [0.8, 10.0]
        mujoco.mj_step(m, d, nstep=500)
        y = tj.read(m, d, "joint")
        assert np.isfinite(d.qpos).all()
        assert y["housing_temperature"] > 295.2 and y["motor_placed"] == 1.0
        # the motor torque went through the transmission: the link's torque follows the motor's
        assert abs(y["transmitted_torque_mean"]) > 0.05


def trajectory(m, d, steps: int, seed: int = 0):
    """Steps under a varying motor torque and heater power; returns every step's full state."""
    rng = np.random.default_rng(seed)
    size = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    out = np.empty((steps, size))
    for i in range(steps):
        d.ctrl[:] = [rng.uniform(-2, 2), rng.uniform(0, 20)]
        mujoco.mj_step(m, d)
        mujoco.mj_getState(m, d, out[i], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    return out


def same_bits(a, b) -> bool:
    """Equal to the bit (gravity's sine anchor in the state is NaN until the model needs it)."""
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def test_reset_keyframe_and_copy_continue_bit_identically():
    m = tj.model_from_xml(scene())
    d = mujoco.MjData(m)
    first = trajectory(m, d, 300)
    assert first[-1, -len(tj.state_names()):].tolist() != first[0, -len(tj.state_names()):].tolist()
    mujoco.mj_resetData(m, d)
    assert same_bits(trajectory(m, d, 300), first)

    # a keyframe: the joint restarts from its configured state at the key's posture
    mujoco.mj_resetDataKeyframe(m, d, 0)
    keyed = trajectory(m, d, 200, seed=1)
    fresh = mujoco.MjData(m)
    fresh.qpos[:] = 0.7
    fresh.qvel[:] = 0.3
    assert same_bits(trajectory(m, fresh, 200, seed=1), keyed)

    # mj_copyData mid-run, and between mj_forward and mj_step: both continue alike
    mujoco.mj_forward(m, d)
    twin = copy.copy(d)  # MjData's copy is mj_copyData
    assert same_bits(trajectory(m, twin, 200, seed=2), trajectory(m, d, 200, seed=2))


def test_rollout_on_two_threads_equals_serial_stepping():
    from mujoco import rollout

    m = tj.model_from_xml(scene())
    d = mujoco.MjData(m)
    trajectory(m, d, 50)  # a warm, moving joint
    rng = np.random.default_rng(3)
    copies, steps = 64, 100
    initial = np.tile(tj.full_state(m, d), (copies, 1))
    initial[:, 1] += rng.uniform(-0.3, 0.3, copies)  # qpos (after time)
    control = np.stack([rng.uniform([-2, 0], [2, 20], (steps, 2)) for _ in range(copies)])
    state, _ = rollout.rollout([m] * copies, [mujoco.MjData(m) for _ in range(2)], initial, control)
    serial = tj.step_serially(m, d, initial, control)
    assert same_bits(state, serial)
    assert np.ptp(state[:, -1, 1]) > 0.1  # the copies went different ways


@pytest.fixture(scope="module")
def arm():
    m = tm.load_arm(tm.DEFAULT_MODEL)
    p = tm.postures(m)
    first = tm.touch_plan(p, 0.2)
    return tm.open_fmu(ROOT / "target" / "fmu" / "ThermoVIA.fmu"), tm.Plan([(0.0, p["home"]), *first[:2]]), first[1][0]


def angles(rec, times):
    return tm._at(rec, times)


def test_the_arm_through_the_plugin_is_the_cosimulation(arm):
    """Cold (a linear transmission), the plugin is the co-simulation's scheme inside mj_step: their
    joint angles agree far inside the co-simulation's own error against the monolithic arm (RK4 at
    0.1 ms), and the plugin's error is no larger."""
    (unzipdir, md), plan, duration = arm
    settings = {j: tm.JointSettings() for j in tm.JOINTS}
    k, c, jm, bm = tm.transmission_at(unzipdir, md, tm.ROOM_C)
    mono_xml = tm.monolithic_xml(tm.DEFAULT_MODEL, {j: k for j in tm.JOINTS}, {j: c for j in tm.JOINTS}, jm, bm)
    ref = tm.run_monolithic(mono_xml, plan, duration, 1e-4, settings, record_every=1, rk4=True)
    times = np.arange(0.05, duration, 0.005)
    for h in (1e-3, 2e-3):
        co = tm.run_cosim(tm.load_arm(tm.DEFAULT_MODEL), unzipdir, md, plan, duration, h, settings, record_every=1)
        native = tm.run_plugin(tm.DEFAULT_MODEL, plan, duration, h, settings, record_every=1)
        cosim_error = np.abs(angles(co, times) - angles(ref, times)).max()
        plugin_error = np.abs(angles(native, times) - angles(ref, times)).max()
        apart = np.abs(angles(native, times) - angles(co, times)).max()
        assert cosim_error > 1e-4, "the reference is distinguishable from the step's error"
        assert apart <= 0.1 * cosim_error, (h, apart, cosim_error)
        assert plugin_error <= cosim_error * (1 + 1e-6), (h, plugin_error, cosim_error)


def test_a_heating_joint_stays_within_the_cosimulations_first_order_error(arm):
    """With the elbow's PCL warming through its softening (from 56 °C, a 120 °C housing and its heater
    on), C_eff moves away from the joint's fixed implicit damping: the plugin and the co-simulation
    differ by O(h), inside the co-simulation's own error (estimated as its change from h to h/2)."""
    (unzipdir, md), plan, _ = arm
    settings = {j: tm.JointSettings(pcl_c=56.0 if j == "elbow" else tm.ROOM_C) for j in tm.JOINTS}
    settings["elbow"].parameters = {"initial_housing_temperature": 120.0 + tm.ZERO_C}
    heated = tm.Plan(plan.waypoints, heater=lambda t, temps: [0.0, 0.0, 50.0])
    duration = 3.0
    times = np.arange(0.05, duration, 0.005)
    # 1 ms: the check at load time counts on the joint cooling back to the 40 °C loss peak, where
    # C_eff = 16 N·m·s/rad against the 2.7 taken implicitly, and refuses 2 ms
    h = 1e-3
    co = tm.run_cosim(tm.load_arm(tm.DEFAULT_MODEL), unzipdir, md, heated, duration, h, settings, record_every=1)
    half = tm.run_cosim(tm.load_arm(tm.DEFAULT_MODEL), unzipdir, md, heated, duration, h / 2, settings, record_every=1)
    native = tm.run_plugin(tm.DEFAULT_MODEL, heated, duration, h, settings, record_every=1)
    assert native.pcl_c[-1][2] > 57.0 and abs(native.pcl_c[-1][2] - co.pcl_c[-1][2]) < 1e-6
    assert native.stiffness[-1][2] < 0.95 * native.stiffness[0][2], "the elbow softened during the run"
    apart = np.abs(angles(native, times) - angles(co, times)).max()
    own = np.abs(angles(co, times) - angles(half, times)).max()
    assert 0.0 < apart <= own, (apart, own)
