"""ThermoVIA joints inside MuJoCo (issue 21): the link-driven mode through fmpy, the three-joint example
on a short horizon, headless, and its refusals of bad input."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

os.environ.setdefault("MUJOCO_GL", "osmesa")
ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "mujoco"
sys.path.insert(0, str(EXAMPLE))
import thermovia_mujoco as tm  # noqa: E402

FMU = ROOT / "target" / "fmu" / "ThermoVIA.fmu"


def test_link_driven_mode_validates_and_simulates_in_fmpy():
    assert validate_fmu(str(FMU)) == []
    # fmpy's own master: the link moves at 0.5 rad/s, the motor is driven by the transmission alone
    t = np.arange(0.0, 0.5, 1e-3)
    inputs = np.array(
        [(x, 0.5 * x, 0.5) for x in t],
        dtype=[("time", float), ("link_angle_command", float), ("link_speed_command", float)],
    )
    r = simulate_fmu(
        str(FMU),
        start_values={"link_drive": 1},
        input=inputs,
        output=["link_angle", "motor_angle", "transmitted_torque_mean"],
        step_size=1e-3,
        stop_time=0.5,
        validate=True,
    )
    assert abs(r["link_angle"][-1] - 0.25) < 2e-3
    # the motor is dragged along through the transmission: it lags the link and the torque on the
    # link is negative (the link pulls the motor)
    assert 0.0 < r["motor_angle"][-1] < r["link_angle"][-1]
    assert r["transmitted_torque_mean"][-1] < 0.0


@pytest.fixture(scope="module")
def fmu():
    return tm.open_fmu(FMU)


@pytest.fixture(scope="module")
def arm():
    m = tm.load_arm(tm.DEFAULT_MODEL)
    return m, tm.postures(m)


def press(fmu, arm, elbow_c: float, h=1e-3):
    """Move above the table and press, with the elbow's PCL at elbow_c from the start: (record, the
    steady contact force over the last 0.3 s of the hold)."""
    m, p = arm
    unzipdir, md = fmu
    settings = {j: tm.JointSettings(pcl_c=elbow_c if j == "elbow" else tm.ROOM_C) for j in tm.JOINTS}
    first = tm.touch_plan(p, 0.3)
    plan = tm.Plan([(0.0, p["home"]), *first[:3]])
    rec = tm.run_cosim(m, unzipdir, md, plan, first[2][0], h, settings, record_every=10)
    t = np.array(rec.t)
    sel = t >= first[2][0] - 0.3
    return rec, float(np.mean(np.array(rec.contact)[sel]))


def test_the_softened_joint_presses_with_a_lower_force_than_the_cold_one(fmu, arm):
    cold, f_cold = press(fmu, arm, tm.ROOM_C)
    soft, f_soft = press(fmu, arm, 62.0)
    k_cold, k_soft = cold.stiffness[-1][2], soft.stiffness[-1][2]
    assert k_soft < 0.5 * k_cold, (k_cold, k_soft)
    assert f_cold > 1.0, f"the cold arm touches the table: {f_cold} N"
    assert f_soft < 0.95 * f_cold, (f_cold, f_soft)


def test_the_example_runs_headless_on_a_short_horizon(tmp_path):
    # 100 W heats the elbow in a few seconds: the whole task, frames and report, in a short run
    out = tmp_path / "mujoco"
    run = subprocess.run(
        [sys.executable, str(EXAMPLE / "thermovia_mujoco.py"), "--out", str(out), "--heater-power", "100",
         "--soft-c", "45", "--no-accuracy", "--max-seconds", "30"],
        capture_output=True, text=True, timeout=600,
    )
    assert run.returncode == 0, run.stderr
    import json

    r = json.loads((out / "report.json").read_text())
    assert r["contact_force_n"]["soft"] < r["contact_force_n"]["cold"]
    assert r["timing"]["real_time_factor"] > 0.0
    for name in r["files"]:
        assert (out / name).stat().st_size > 0, name
    if "frames.png" not in r["files"]:
        assert "unavailable" in r["frames"], r["frames"]
    assert "# ThermoVIA joints in MuJoCo" in (out / "report.md").read_text()


def test_the_coupling_converges_to_the_monolithic_arm(fmu, arm):
    m, p = arm
    unzipdir, md = fmu
    settings = {j: tm.JointSettings() for j in tm.JOINTS}
    plan = tm.Plan([(0.0, p["home"]), (0.3, p["above"])])
    study = tm.accuracy_study(tm.DEFAULT_MODEL, unzipdir, md, plan, 0.5, settings, steps=(0.5e-3, 2e-3))
    fine, coarse = study["rows"]
    # no contact in this move: the error is the coupling's and the engine's step, first order in
    # the step (a quarter of the step, a quarter of the error)
    ratio = coarse["cosim_max_angle_error_rad"] / fine["cosim_max_angle_error_rad"]
    assert 3.0 < ratio < 5.5, (fine, coarse)
    assert fine["coupling_max_angle_error_rad"] < coarse["coupling_max_angle_error_rad"] / 3.0, (fine, coarse)
    assert fine["cosim_max_angle_error_rad"] < 5e-3, fine


def test_a_model_without_the_named_joints_is_refused_with_their_names(tmp_path):
    xml = tmp_path / "two.xml"
    xml.write_text(
        '<mujoco><worldbody><body><joint name="base_yaw" type="hinge"/><geom size="0.1"/>'
        '<body><joint name="knee" type="hinge"/><geom size="0.1"/></body></body></worldbody></mujoco>'
    )
    with pytest.raises(tm.CouplingError) as e:
        tm.load_arm(xml)
    assert "no joint named shoulder, elbow" in str(e.value) and "base_yaw, knee" in str(e.value)
    run = subprocess.run(
        [sys.executable, str(EXAMPLE / "thermovia_mujoco.py"), "--out", str(tmp_path / "o"), "--model", str(xml)],
        capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == 2 and "no joint named shoulder, elbow" in run.stderr, run.stderr
    assert not (tmp_path / "o").exists()


def test_a_step_above_the_stability_limit_is_refused_with_the_limit(fmu, arm):
    m, _ = arm
    unzipdir, md = fmu
    settings = {j: tm.JointSettings() for j in tm.JOINTS}
    limit = tm.check_step(m, unzipdir, md, 1e-3, settings)["limit_s"]
    with pytest.raises(tm.CouplingError) as e:
        tm.check_step(m, unzipdir, md, 1.5 * limit, settings)
    assert "stability limit" in str(e.value) and f"{limit:.4g}" in str(e.value)
    # and the limit is real: the linearised map is unstable just above it, stable below
    k, c, jm, bm = tm.transmission_at(unzipdir, md, 62.0)
    j = tm.effective_inertias(m)["shoulder"]
    kw = dict(k=k, c=c, j_link=j, j_motor=jm, b_motor=bm, kp=150.0, kd=1.5)
    lim = tm.stability_limit(**kw)
    assert tm.stable(0.9 * lim, **kw) and not tm.stable(1.1 * lim, **kw)


def test_a_missing_rendering_backend_skips_the_frames_and_says_so(tmp_path):
    env = dict(os.environ, MUJOCO_GL="no-such-backend")
    out = tmp_path / "mujoco"
    run = subprocess.run(
        [sys.executable, str(EXAMPLE / "thermovia_mujoco.py"), "--out", str(out), "--heater-power", "100",
         "--soft-c", "40", "--no-accuracy", "--max-seconds", "30"],
        capture_output=True, text=True, timeout=600, env=env,
    )
    assert run.returncode == 0, run.stderr
    import json

    r = json.loads((out / "report.json").read_text())
    assert "unavailable" in r["frames"] and "frames.png" not in r["files"], r["frames"]
    assert "Frames: off-screen rendering unavailable" in (out / "report.md").read_text()


THERMOVIA = ROOT / "target" / "release" / "thermovia"


def test_the_two_link_arm_through_mujoco_agrees_with_thermovia_arm(fmu, tmp_path):
    import json

    assert THERMOVIA.exists(), "cargo build --release --bin thermovia (cargo test builds it)"
    run = subprocess.run([str(THERMOVIA), "arm", "--out", str(tmp_path / "arm")], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    report = json.loads((tmp_path / "arm" / "report.json").read_text())
    x = tm.two_link_crosscheck(report, *fmu, h=1e-3)
    assert [r["scenario"] for r in x["rows"]] == ["cold", "hot"]
    for r in x["rows"]:
        mj, ta = r["mujoco"], r["thermovia_arm"]
        # the two co-simulations differ by at most twice thermovia arm's own coupling error at 1 ms
        allowed = 2.0 * r["thermovia_arm_coupling_error"]["peak_force_error_n"]
        assert abs(mj["peak_contact_force_n"] - ta["peak_contact_force_n"]) <= allowed, r
        assert abs(mj["final_contact_force_n"] - ta["final_contact_force_n"]) <= 0.01, r
        assert abs(mj["first_contact_s"] - ta["first_contact_s"]) <= 3e-3 + 1e-9, r
    cold, hot = x["rows"]
    assert hot["mujoco"]["peak_contact_force_n"] < 0.6 * cold["mujoco"]["peak_contact_force_n"]
