"""Three more independent FMI 2.0 Co-Simulation importers run the packaged FMU and must reproduce fmpy's
simulate_fmu: fmu-manipulation-toolbox's compiled FMU Container (ThermoVIA inside another FMU, the
container run by fmpy), OSP libcosim (libcosimpy) and ecos (ecospy).

Same setup everywhere: 10 s at a 1 ms communication step, heater_power = 10 W, motor_torque = 0.1 N·m,
everything else at its default. Samples are compared by step index k (time k·1 ms) after each importer's
own clock is checked against that grid. They are not bit-identical because the importers pass slightly
different step sizes to fmi2DoStep:
  fmpy       doStep(t_k, (k+1)·0.001 − k·0.001) with t_k = k·0.001 (h varies in the last bits)
  container  h = 0.001 exactly (its internal fixed step)
  libcosim   integer nanoseconds: doStep(k/1000, (k+1)/1000 − k/1000)
  ecos       h = 0.001 exactly; its clock is a running sum (drifts ~1e-12 s over 10 000 steps)
so ~1e-11 differences are expected; the tolerance is 1e-9 absolute.

Each importer is imported inside its test: a missing package fails that test (ImportError), never skips.
"""
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu

FMU = Path(__file__).resolve().parents[2] / "target" / "fmu" / "ThermoVIA.fmu"

STEP, STOP = 1e-3, 10.0
STEPS = int(round(STOP / STEP))  # 10 000 communication steps
INPUTS = {"heater_power": 10.0, "motor_torque": 0.1}
OUTPUTS = ["link_angle", "pcl_temperature"]
TOL = 1e-9


def run_fmpy(path):
    return simulate_fmu(str(path), stop_time=STOP, step_size=STEP, output_interval=STEP, start_values=INPUTS,
                        output=OUTPUTS)


@pytest.fixture(scope="module")
def reference():
    assert FMU.exists(), "run `cargo run --release -p fmu-build` first"
    result = run_fmpy(FMU)
    assert len(result) == STEPS + 1
    np.testing.assert_allclose(result["time"], np.arange(STEPS + 1) * STEP, rtol=0, atol=1e-12)
    return result


def check_against(reference, name, times, values, first):
    """values[n][i] is output n at sample time times[i] = (first + i)·STEP; compare with fmpy's rows first..."""
    ref = reference[first:first + len(times)]
    assert len(times) == len(ref) == STEPS + 1 - first, f"{name}: {len(times)} samples"
    np.testing.assert_allclose(times, ref["time"], rtol=0, atol=1e-9, err_msg=f"{name}: time grid")
    diffs = {n: float(np.max(np.abs(np.asarray(values[n]) - ref[n]))) for n in OUTPUTS}
    print(f"{name}: max |diff| vs fmpy " + ", ".join(f"{n} {d:.3g}" for n, d in diffs.items()))
    for n, d in diffs.items():
        assert d <= TOL, f"{name}: {n} differs from fmpy by {d:.3g}"
    # the run must actually move: the motor turns the link and the heater warms the PCL
    assert np.ptp(values["link_angle"]) > 1.0, f"{name}: link_angle does not move"
    assert values["pcl_temperature"][-1] - reference["pcl_temperature"][0] > 1.0, f"{name}: PCL does not heat"
    return diffs


def test_fmu_manipulation_toolbox_container_run_by_fmpy(reference, container_fmu):
    from fmpy import read_model_description

    md = read_model_description(str(container_fmu))
    assert md.coSimulation.modelIdentifier == "ThermoVIAContainer"
    names = {v.name for v in md.modelVariables}
    assert set(INPUTS) | set(OUTPUTS) <= names
    result = run_fmpy(container_fmu)
    check_against(reference, "fmu-manipulation-toolbox container", result["time"],
                  {n: result[n] for n in OUTPUTS}, first=0)


def test_libcosim(reference):
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    step_ns = int(round(STEP * 1e9))  # libcosim's clock is integer nanoseconds
    execution = CosimExecution.from_step_size(step_size=step_ns)
    index = execution.add_local_slave(CosimLocalSlave(fmu_path=str(FMU), instance_name="thermovia"))
    variables = {v.name.decode(): v.reference for v in execution.slave_variables(index)}
    # Known limitation: libcosim drops FMI 2.0 Enumeration variables, so motor_drive, thermal_drive and
    # material_table cannot be set (they stay at their start values). If this starts failing after an
    # upgrade, update docs/fmi.md ("The three importers in detail").
    assert "motor_drive" not in variables and "heater_power" in variables
    # inputs as initial values: set before initialization, and nothing overwrites them afterwards
    for name, value in INPUTS.items():
        assert execution.real_initial_value(index, variables[name], value), name
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    refs = [variables[n] for n in OUTPUTS]
    times, rows = [], []
    for k in range(1, STEPS + 1):  # one step at a time; the last-value observer gives the post-step outputs
        assert execution.step(1), f"step {k}"
        now_ns = execution.status().current_time
        assert now_ns == k * step_ns
        times.append(now_ns * 1e-9)
        rows.append(observer.last_real_values(index, refs))
    rows = np.array(rows)
    check_against(reference, "libcosim", np.array(times), {n: rows[:, j] for j, n in enumerate(OUTPUTS)}, first=1)


def test_ecos(reference):
    from ecospy import EcosLib, EcosSimulation, EcosSimulationStructure

    EcosLib.set_log_level("warn")
    structure = EcosSimulationStructure()
    structure.add_model("thermovia", str(FMU))
    sim = EcosSimulation(structure=structure, step_size=STEP)
    try:
        # Known limitation: ecos has no access to FMI 2.0 Enumeration variables either.
        with pytest.raises(Exception, match="motor_drive"):
            sim.get_integer("thermovia::motor_drive")
        for name, value in INPUTS.items():  # set before init; held for the whole run
            sim.set_real(f"thermovia::{name}", value)
        sim.init()
        ids = [f"thermovia::{n}" for n in OUTPUTS]
        times, rows = [sim.get_time()], [[sim.get_real(i) for i in ids]]
        for _ in range(STEPS):
            times.append(sim.step())
            rows.append([sim.get_real(i) for i in ids])
        sim.terminate()
    finally:
        sim.free()
        structure.free()
    rows = np.array(rows)
    check_against(reference, "ecos", np.array(times), {n: rows[:, j] for j, n in enumerate(OUTPUTS)}, first=0)
