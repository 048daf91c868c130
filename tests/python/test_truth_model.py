"""The independent truth model (tests/truth/truth_model.py) is right before anything is judged by
it: its linear steady state matches the analytic transfer function, RK4 converges at its default
step, and its backlash is a clipped spring–damper (dead zone, a damper that never pulls; Modelica's ElastoBacklash also caps the damping by the spring torque); the other
effects, excitations, initial speed and timestamp jitter do what truth.json says they do."""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "truth"))
import truth_model as tm  # noqa: E402


def steady_amplitude(t, x, w, t0, cycles=4):
    sel = (t >= t0) & (t < t0 + cycles * 2 * math.pi / w - 1e-9)  # whole cycles: no end point twice
    c = np.cos(w * t[sel])
    s = np.sin(w * t[sel])
    a = 2 * np.mean(x[sel] * s)
    b = 2 * np.mean(x[sel] * c)
    return math.hypot(a, b), math.atan2(b, a)


def test_linear_steady_state_matches_the_transfer_function():
    k, c, j, amp, f = 20.0, 0.3, 0.018, 0.3, 1.0
    w = 2 * math.pi * f
    p = {"stiffness": k, "damping": c, "inertia": j}
    t, x, _ = tm.simulate(p, 12.0, 1e-4, lambda t: (amp * math.sin(w * t), amp * w * math.cos(w * t)))
    h = complex(k, w * c) / complex(k - j * w * w, w * c)
    got, phase = steady_amplitude(t, x, w, 8.0)  # 4 whole cycles after the transient (τ = 2J/C ≈ 0.12 s)
    assert abs(got - amp * abs(h)) < 1e-6 * amp, (got, amp * abs(h))
    assert abs(phase - math.atan2(h.imag, h.real)) < 1e-5


def test_rk4_converges_at_the_default_step_for_a_stiff_transmission():
    p = {"stiffness": 680.0, "damping": 0.1, "inertia": 0.018, "backlash": 0.0}
    m = lambda t: (0.3 * math.sin(2 * math.pi * t), 0.3 * 2 * math.pi * math.cos(2 * math.pi * t))  # noqa: E731
    _, coarse, _ = tm.simulate(dict(p), 2.0, 1e-4, m)
    _, fine, _ = tm.simulate(dict(p), 2.0, 5e-5, m)
    assert np.max(np.abs(coarse - fine[::2])) < 1e-8


def test_backlash_is_a_dead_zone_whose_damper_never_pulls():
    p = {"stiffness": 30.0, "damping": 2.0, "inertia": 0.018, "backlash": 0.02}
    assert tm.link_torque(0.005, 5.0, 0.0, dict(p)) == 0.0  # inside the play: nothing, whatever the speed
    assert math.isclose(tm.link_torque(0.015, 0.0, 0.0, dict(p)), 30.0 * 0.005)  # beyond it: the spring on the excess
    assert tm.link_torque(0.0101, -10.0, 0.0, dict(p)) == 0.0  # separating fast: the damper does not pull
    assert math.isclose(tm.link_torque(-0.015, 0.0, 0.0, dict(p)), -30.0 * 0.005)


def read_run(path):
    lines = path.read_text().splitlines()
    meta = dict(line[2:].strip().split("=", 1) for line in lines if line.startswith("# "))
    body = [line for line in lines if not line.startswith("#")]
    cols = body[0].split(",")
    d = np.array([[float(x) for x in line.split(",")] for line in body[1:]])
    return d[:, cols.index("time_s")], d[:, cols.index("motor_angle_rad")], d[:, cols.index("link_angle_rad")], meta


def phasors(t, x, freqs):
    """x = c + Σ a_i sin(ω_i t) + b_i cos(ω_i t) by least squares → a_i + j b_i (sin is the phase reference)."""
    cols = [np.ones_like(t)] + [g(2 * math.pi * f * t) for f in freqs for g in (np.sin, np.cos)]
    coef, *_ = np.linalg.lstsq(np.column_stack(cols), x, rcond=None)
    return np.array([complex(coef[1 + 2 * i], coef[2 + 2 * i]) for i in range(len(freqs))])


def test_the_multisine_run_follows_the_transfer_function_at_each_of_its_frequencies(tmp_path):
    k, c, j = 20.0, 0.3, 0.018
    tm.main(["--out", str(tmp_path), "--excitation", "multisine", "--temperatures", "40", "--stiffness", str(k),
             "--damping", str(c), "--frequencies", "1", "--duration", "7", "--noise", "0", "--quantum", "0"])
    truth = json.loads((tmp_path / "truth.json").read_text())
    (run,) = truth["runs"]
    assert "frequency_hz" not in run and truth["effects"] == {} and truth["excitation"] == "multisine"
    t, motor, link, meta = read_run(tmp_path / run["file"])
    assert "frequency_hz" not in meta
    ex = run["excitation"]
    freqs = ex["frequencies_hz"]
    assert len(freqs) >= 3 and min(freqs) >= 0.2 and max(freqs) <= 3.0
    sel = (t >= 2.0) & (t < 7.0 - 1e-9)  # 5 s: whole cycles of every component; the transient is e^-17 gone
    m, y = phasors(t[sel], motor[sel], freqs), phasors(t[sel], link[sel], freqs)
    assert np.allclose(np.abs(m), ex["amplitudes_rad"], rtol=1e-9)  # the motor is what truth.json declares
    for f, mi, yi in zip(freqs, m, y):
        w = 2 * math.pi * f
        h = complex(k, w * c) / complex(k - j * w * w, w * c)
        assert abs(yi / mi - h) < 1e-5 * abs(h), (f, yi / mi, h)


def test_a_large_friction_on_a_light_link_holds_it_creeping_as_the_smoothed_law_says():
    # campaign rig 173's friction and inertia: F/(v_s J) = 1.3e5 /s, 12.7 times past 1/h at the default
    # step, where unsplit RK4 chatters about zero speed. Under a load τ < F the exact link creeps at
    # v_s atanh(τ/F) once the speed has settled (at F sech²/(v_s J), within microseconds).
    f, j, vs, load = 1.127, 0.00887, 1e-3, 0.128
    p = {"stiffness": 0.0, "damping": 0.0, "inertia": j, "constant_load": load,
         **tm.parse_effects([f"coulomb_friction={f}"])}
    assert tm.friction_rate(p) * 1e-4 > 10
    t, x, v = tm.simulate(p, 0.5, 1e-4, lambda t: (0.0, 0.0))
    creep = vs * math.atanh(load / f)
    settled = t >= 0.01
    assert np.max(np.abs(v[settled] / creep - 1)) < 1e-6, (v[settled].min(), v[settled].max(), creep)
    assert abs((x[-1] - x[np.argmax(settled)]) / (creep * (t[-1] - 0.01)) - 1) < 1e-6


def test_asymmetric_friction_decelerates_each_direction_by_its_own_levels():
    j = 0.018
    fp, fn, bp, bn = 0.06, 0.03, 0.02, 0.01
    p = {"stiffness": 0.0, "damping": 0.0, "inertia": j, **tm.parse_effects([f"asymmetric_friction={fp},{fn},{bp},{bn}"])}
    still = lambda t: (0.0, 0.0)  # noqa: E731
    end = {}
    for v0, f, b in ((1.0, fp, bp), (-1.0, fn, bn)):
        t, x, _ = tm.simulate(dict(p, initial_link_speed=v0), 0.2, 1e-4, still)
        # J v' = −(F sgn v + B v) while v keeps its sign: v(t) = (v0 ± F/B) e^{−Bt/J} ∓ F/B
        s = math.copysign(1.0, v0)
        exact = (v0 + s * f / b) * (j / b) * (1 - np.exp(-b * t / j)) - s * f / b * t
        assert np.max(np.abs(x - exact)) < 1e-7, v0
        end[v0] = x[-1]
    # the same 1 rad/s start loses different distance in 0.2 s each way: 0.083 rad forwards, 0.043 backwards
    assert 1.8 < (0.2 - end[1.0]) / (0.2 + end[-1.0]) < 2.1, end


def test_hardening_spring_constant_load_and_effect_names():
    p = {"stiffness": 20.0, "damping": 0.0, "inertia": 0.018, "hardening_alpha": 100.0}
    assert math.isclose(tm.link_torque(0.1, 0.0, 0.0, dict(p)), 20.0 * 0.1 * (1 + 100.0 * 0.01))
    assert math.isclose(tm.link_torque(-0.11, 0.0, 0.0, dict(p, backlash=0.02)), -20.0 * 0.1 * (1 + 100.0 * 0.01))
    # a constant load settles the link at τ0/K against the transmission
    t, x, _ = tm.simulate({"stiffness": 20.0, "damping": 0.3, "inertia": 0.018, "constant_load": 0.1}, 3.0, 1e-4,
                       lambda t: (0.0, 0.0))
    assert abs(x[-1] - 0.1 / 20.0) < 1e-8
    flat = tm.parse_effects(["coulomb_friction=0.02", "stribeck=0.03,0.05", "asymmetric_friction=0.06,0.03,0.02,0.01",
                             "constant_load=-0.1", "gravity_mgl=1.2", "gravity_offset=0.1", "backlash=0.02",
                             "link_damping=0.01", "hardening=100"])
    assert tm.effects_json(flat) == {
        "coulomb_friction": {"torque_nm": 0.02},
        "stribeck_friction": {"torque_nm": 0.03, "velocity": 0.05},
        "asymmetric_friction": {"coulomb_positive": 0.06, "coulomb_negative": 0.03, "viscous_positive": 0.02,
                                "viscous_negative": 0.01},
        "constant_load": {"torque_nm": -0.1},
        "backlash": {"width_rad": 0.02},
        "gravity": {"mgl_nm": 1.2, "offset_rad": 0.1},
        "link_damping": {"damping_nms": 0.01},
        "hardening_spring": {"alpha_per_rad2": 100.0, "out_of_library": True},
    }
    for bad in ("stribeck=0.03", "bogus=1", "asymmetric_friction=1,2,3", "backlash=x"):
        with pytest.raises(ValueError):
            tm.parse_effects([bad])


@pytest.mark.parametrize("kind", ["sine", "multisine", "steps"])
def test_the_motor_speed_is_the_derivative_of_the_motor_angle(kind):
    motor, _ = tm.excitation(kind, 0.3, 1.0, 10.0, np.random.default_rng(3), moving=True)
    h = 1e-6
    for t in np.linspace(0.0, 10.0, 397):
        fd = (motor(t + h)[0] - motor(t - h)[0]) / (2 * h)
        assert abs(fd - motor(t)[1]) < 1e-6 * (1 + abs(fd)), (kind, t)
    if kind == "steps":
        xs = [motor(t)[0] for t in np.linspace(0, 10, 1001)]
        assert max(xs) <= 0.3 + 1e-9 and min(xs) >= -0.3 - 1e-9 and max(xs) - min(xs) > 0.1


def test_a_moving_start_and_timestamp_jitter(tmp_path):
    rate, jitter = 1000.0, 0.3
    tm.main(["--out", str(tmp_path), "--temperatures", "40", "--stiffness", "20", "--damping", "0.3",
             "--frequencies", "1", "--duration", "0.5", "--noise", "0", "--quantum", "0", "--jitter", str(jitter),
             "--initial-speed", "0.5"])
    truth = json.loads((tmp_path / "truth.json").read_text())
    (run,) = truth["runs"]
    assert run["file"] == "run_40C_1Hz.csv" and run["frequency_hz"] == 1.0 and truth["initial_link_speed"] == 0.5
    t, motor, link, _ = read_run(tmp_path / run["file"])
    grid = np.arange(t.size) / rate
    err = (t - grid) * rate
    assert np.all(np.diff(t) > 0) and np.max(np.abs(err)) <= jitter and np.std(err) > 0.1  # logged times are off
    assert abs(motor[0] - 0.3 * math.sin(math.pi / 4)) < 1e-12 and link[0] == motor[0]  # mid-swing, spring relaxed
    # the samples sit on the uniform grid, not at the jittered times: the motor column is exactly the sine there
    assert np.max(np.abs(motor - 0.3 * np.sin(2 * math.pi * grid + math.pi / 4))) < 1e-12
    assert abs((link[1] - link[0]) * rate - 0.5) < 0.02  # the link starts at 0.5 rad/s


def replay_rms(tmp_path, *args):
    out = tmp_path / "replay"
    tm.main(["--out", str(out), "--temperatures", "22", "--stiffness", "34", "--damping", "0.4", "--frequencies", "1",
             "--duration", "3", "--effect", "backlash=0.02", "--replay", *args])
    truth = json.loads((out / "truth.json").read_text())
    floor = math.sqrt(truth["noise"] ** 2 + truth["quantum"] ** 2 / 12)
    rms = tm.replay_rms(out)
    assert json.loads((out / "truth.json").read_text())["replay_rms"] == rms  # kept for the next caller
    return rms, floor


def test_replay_of_a_clean_log_is_the_truth(tmp_path):
    # a log without noise, counts, jitter or gaps: the replay differs only by the straight line
    # between samples of the motor angle (1 kHz, a 1 Hz sine of 0.3 rad: about 1e-6 rad)
    rms, _ = replay_rms(tmp_path, "--noise", "0", "--quantum", "0")
    assert rms < 1e-5


def test_replay_counts_the_motor_encoder_and_the_jitter(tmp_path):
    # coarse counts on steps: the motor's reading is off by up to half a count while it holds, the
    # link's again; jitter moves every sample in time. Each puts the replay above the link sensor's floor.
    rms, floor = replay_rms(tmp_path, "--noise", "1e-5", "--quantum", "0.003", "--excitation", "steps",
                            "--duration", "8")
    assert rms > 1.1 * floor
    rms, floor = replay_rms(tmp_path, "--noise", "1e-5", "--quantum", "0", "--jitter", "0.2")
    assert rms > 3 * floor
