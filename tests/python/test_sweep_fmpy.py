"""The sweep's master, driven by fmpy instead of the Rust harness, on a short condition: the link's
response over whole steady cycles matches K*/(K* − J_l ω²) at the values the FMU reports."""

import cmath
import math
import os
import sys

import pytest
from fmpy import extract, read_model_description

sys.path.insert(0, os.path.dirname(__file__))
import sweep_fmpy_bench as bench  # noqa: E402

FMU = os.path.join(os.path.dirname(__file__), "..", "..", "target", "fmu", "ThermoVIA.fmu")


@pytest.fixture(scope="module")
def fmu():
    md = read_model_description(FMU)
    d = extract(FMU)
    yield md, d
    import shutil
    shutil.rmtree(d, ignore_errors=True)


def test_fmpy_driven_sweep_matches_the_frequency_response(fmu):
    md, d = fmu
    o = dict(bench.DEFAULTS, temperatures=[22.0], frequencies=[1.0], settle_cycles=4, cycles=2)
    [r] = bench.sweep(FMU, o, md, d)
    # values the FMU uses at 22 °C, 1 Hz
    sim = bench.Sim(md, d, "probe", {"excitation_frequency": 1.0})
    k, c, jl = sim.fmu.getReal([sim.vr["effective_stiffness"], sim.vr["effective_damping"], sim.vr["link_inertia"]])
    sim.free()
    w = 2 * math.pi
    ks = complex(k, w * c)
    h_an = ks / (ks - jl * w * w)
    h = complex(r["h_re"], r["h_im"])
    # H − 1 (Decay and phase together) within 0.5 %: |H| alone is ≈ 1 and would prove nothing
    assert abs(h - h_an) < 5e-3 * abs(h_an - 1)
    assert r["decay_rad"] < 0  # springs + Kelvin–Voigt: the link overshoots below √2 f_n
    assert r["phase_deg"] == pytest.approx(-math.degrees(cmath.phase(h_an)), rel=5e-3)


def test_sweep_csvs_load_with_fmpy_read_csv(tmp_path):
    """The trajectory CSVs of `thermovia sweep` are in fmpy's result layout."""
    import subprocess
    from fmpy.util import read_csv

    exe = os.path.join(os.path.dirname(__file__), "..", "..", "target", "release", "thermovia")
    out = tmp_path / "sweep"
    subprocess.run([exe, "sweep", "--out", str(out), "--temperatures", "22", "--frequencies", "1",
                    "--settle-cycles", "1", "--cycles", "1", "--quiet"], check=True)
    r = read_csv(str(out / "run_22C_1Hz.csv"))
    assert r.dtype.names[0] == "time"
    assert {"motor_angle", "link_angle", "motor_torque", "housing_temperature"} <= set(r.dtype.names)
    assert len(r) == 2001 and r["time"][-1] == pytest.approx(2.0)
    assert abs(r["link_angle"]).max() > 0.5  # 30° motor amplitude, link follows
