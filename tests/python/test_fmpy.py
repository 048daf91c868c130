"""fmpy checks of the packaged FMU: validation, simulate_fmu against the Rust harness, an FMU
state serialized by fmpy and restored into a fresh instance, and the example on the FMU's own page.
fmpy is imported at module level on purpose: without it this file fails to collect, so CI fails
instead of skipping."""
import math
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.util import read_csv
from fmpy.validation import validate_fmu

ROOT = Path(__file__).resolve().parents[2]
FMU = ROOT / "target" / "fmu" / "ThermoVIA.fmu"
THERMOVIA = ROOT / "target" / "release" / "thermovia"
OUTPUTS = ["motor_angle", "link_angle", "link_speed", "transmitted_torque", "housing_temperature", "pcl_temperature"]


def test_packaged_fmu_exists():
    assert FMU.exists(), "run `cargo run --release -p fmu-build` first"


def test_validate_reports_zero_problems():
    assert validate_fmu(str(FMU)) == []
    fmpy_cli = Path(sys.executable).parent / "fmpy"
    run = subprocess.run([str(fmpy_cli), "validate", str(FMU)], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr


def inputs(step, stop):
    t = np.arange(int(round(stop / step)) + 1) * step
    heater = 6.0 + 4.0 * np.sin(2 * math.pi * 0.2 * t)
    torque = 0.8 * np.sin(2 * math.pi * 1.0 * t) + 0.3 * np.sin(2 * math.pi * 3.7 * t)
    return np.array(list(zip(t, heater, torque)), dtype=[("time", "f8"), ("heater_power", "f8"), ("motor_torque", "f8")])


def test_simulate_fmu_gives_the_rust_harness_trajectories(tmp_path):
    step, stop = 1e-3, 3.0
    signals = inputs(step, stop)
    fmpy_result = simulate_fmu(str(FMU), stop_time=stop, step_size=step, output_interval=step, input=signals, output=OUTPUTS)
    csv_in = tmp_path / "inputs.csv"
    np.savetxt(csv_in, np.column_stack([signals[n] for n in signals.dtype.names]), delimiter=",",
               header=",".join(f'"{n}"' for n in signals.dtype.names), comments="", fmt="%.17g")
    csv_out = tmp_path / "rust.csv"
    subprocess.run([str(THERMOVIA), "simulate", str(FMU), "--input", str(csv_in), "--out", str(csv_out),
                    "--stop-time", str(stop), "--step", str(step), "--output", ",".join(OUTPUTS)], check=True)
    rust_result = read_csv(str(csv_out))
    assert len(rust_result) == len(fmpy_result) == 3001
    np.testing.assert_allclose(rust_result["time"], fmpy_result["time"], rtol=0, atol=1e-12)
    assert np.ptp(fmpy_result["link_angle"]) > 0.05, "the run must move"
    assert np.ptp(fmpy_result["housing_temperature"]) > 1.0, "and heat"
    for name in OUTPUTS:
        np.testing.assert_array_equal(rust_result[name], fmpy_result[name], err_msg=name)  # same steps, same bits


@pytest.fixture
def unpacked():
    md = read_model_description(str(FMU))
    directory = extract(str(FMU))
    yield md, directory
    shutil.rmtree(directory, ignore_errors=True)


def new_slave(md, directory, name):
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=directory, modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu


def run(fmu, vr, k0, steps, step=1e-3):
    rows = []
    for k in range(k0, k0 + steps):
        t = k * step
        fmu.setReal([vr["heater_power"], vr["motor_torque"]], [8.0 if (k // 500) % 2 == 0 else 0.0, math.sin(2.0 * t)])
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=step)
        rows.append(fmu.getReal([vr[n] for n in OUTPUTS]))
    return rows


def test_state_serialized_by_fmpy_continues_bit_identically_in_a_fresh_instance(unpacked):
    md, directory = unpacked
    vr = {v.name: v.valueReference for v in md.modelVariables}
    a = new_slave(md, directory, "a")
    run(a, vr, 0, 1000)
    state = a.getFMUState()
    blob = a.serializeFMUState(state)
    expected = run(a, vr, 1000, 1500)

    b = new_slave(md, directory, "b")
    restored = b.deserializeFMUState(blob)
    b.setFMUState(restored)
    assert run(b, vr, 1000, 1500) == expected  # bit-identical, not approximately equal

    a.setFMUState(state)
    assert run(a, vr, 1000, 1500) == expected
    for fmu, st in ((a, state), (b, restored)):
        fmu.freeFMUState(st)
        fmu.terminate()
        fmu.freeInstance()


def test_the_example_on_the_fmus_page_prints_what_it_says(tmp_path, monkeypatch, capsys):
    """documentation/index.html's fmpy example, run as a user would, next to ThermoVIA.fmu: it prints
    what its last comment says."""
    with zipfile.ZipFile(FMU) as archive:
        page = ET.fromstring(archive.read("documentation/index.html"))
    code = page.find(".//{http://www.w3.org/1999/xhtml}pre[@class='example']").text
    shutil.copy(FMU, tmp_path / "ThermoVIA.fmu")
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "documentation/index.html", "exec"), {})
    promised = code.rstrip().splitlines()[-1].rsplit("# ", 1)[1]
    printed = capsys.readouterr().out.strip().splitlines()  # fmpy's warnings, then the example's line
    assert printed[-1] == promised
