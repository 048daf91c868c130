"""`thermovia info` and `thermovia simulate` on an FMU that is not ThermoVIA: the container that
fmu-manipulation-toolbox builds around it (its own model name, GUID, value references, capabilities
and an `independent` time variable). Nothing of ThermoVIA's names or defaults may leak in: the
defaults come from the container's own DefaultExperiment and outputs, and the result must equal
fmpy's simulate_fmu of the same container."""
import subprocess
from pathlib import Path

import numpy as np
from fmpy import read_model_description, simulate_fmu
from fmpy.util import read_csv

THERMOVIA = Path(__file__).resolve().parents[2] / "target" / "release" / "thermovia"


def test_info_describes_the_container(container_fmu):
    run = subprocess.run([str(THERMOVIA), "info", str(container_fmu)], capture_output=True, text=True, check=True)
    text = run.stdout
    md = read_model_description(str(container_fmu))
    assert f"Model          {md.modelName} (FMI 2.0 Co-Simulation)" in text, text
    assert md.guid in text
    assert "canGetAndSetFMUstate                     false" in text, text
    assert f"Variables ({len(md.modelVariables)})" in text, text
    rows = {line.split()[0]: line.split() for line in text.splitlines() if line.startswith("  ") and len(line.split()) > 3}
    for v in md.modelVariables:
        assert rows[v.name][1] == v.causality, (v.name, rows[v.name])
    assert md.defaultExperiment.stopTime is not None
    assert f"stop time    {float(md.defaultExperiment.stopTime):g}" in text, text


def test_simulate_runs_the_container_like_fmpy(container_fmu, tmp_path):
    out = tmp_path / "container.csv"
    stop = 0.5
    subprocess.run([str(THERMOVIA), "simulate", str(container_fmu), "--stop-time", str(stop), "--set", "heater_power=10",
                    "--set", "motor_torque=0.1", "--out", str(out)], check=True, capture_output=True)
    ours = read_csv(str(out))
    md = read_model_description(str(container_fmu))
    step = float(md.defaultExperiment.stepSize)
    reference = simulate_fmu(str(container_fmu), stop_time=stop, output_interval=step,
                             start_values={"heater_power": 10.0, "motor_torque": 0.1})
    # the container's outputs, in its own order, are the default
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    assert list(ours.dtype.names) == ["time"] + outputs
    assert len(ours) == len(reference) == int(round(stop / step)) + 1
    np.testing.assert_allclose(ours["time"], reference["time"], rtol=0, atol=1e-12)
    assert ours["pcl_temperature"][-1] > ours["pcl_temperature"][0] + 0.01, "heated"
    assert ours["link_angle"][-1] > 1e-4, "driven"
    for name in outputs:
        np.testing.assert_array_equal(ours[name], reference[name], err_msg=name)


def test_unknown_names_of_the_container_get_its_own_suggestions(container_fmu):
    run = subprocess.run([str(THERMOVIA), "simulate", str(container_fmu), "--set", "motor_drive=1"],
                         capture_output=True, text=True)
    assert run.returncode != 0
    # the container hides ThermoVIA's parameters: motor_drive is not one of its variables
    assert 'no variable named "motor_drive"' in run.stderr, run.stderr
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr
