"""fmpy driving ThermoVIA with the same loop as benches/dostep.rs (set motor_torque, doStep 1 ms,
get link_angle). Prints the median ns per step of several 20 s runs on its last line."""
import math
import shutil
import statistics
import sys
import time

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

STEP, STEPS = 1e-3, 20_000


def run(path, md, unzipdir):
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    torque, link = [vr["motor_torque"]], [vr["link_angle"]]
    w = 2 * math.pi * 0.5
    start = time.perf_counter()
    for k in range(STEPS):
        t = k * STEP
        fmu.setReal(torque, [2.0 * math.sin(w * t)])
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=STEP)
        fmu.getReal(link)
    elapsed = time.perf_counter() - start
    fmu.terminate()
    fmu.freeInstance()
    return elapsed * 1e9 / STEPS


def main():
    path = sys.argv[1]
    md = read_model_description(path)
    unzipdir = extract(path)
    try:
        samples = [run(path, md, unzipdir) for _ in range(5)]
    finally:
        shutil.rmtree(unzipdir, ignore_errors=True)
    print(f"{statistics.median(samples):.1f}")


if __name__ == "__main__":
    main()
