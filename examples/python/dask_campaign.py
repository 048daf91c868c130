"""A design-of-experiments campaign of the packaged FMU on Dask distributed.

Each task simulates one point of the grid temperature × frequency × load × parameter with fmpy and
returns a few numbers (steady link amplitude and phase against the motor, peak transmitted
torque). Locally the campaign runs on a LocalCluster; on a cluster, give the scheduler's address.
The FMU's bytes are sent to the workers once (scattered), and each worker unpacks it once, so the
workers need no shared file system, only the pinned Python packages (tests/python/requirements.txt).

  .venv/bin/python examples/python/dask_campaign.py                       # LocalCluster, every core
  .venv/bin/python examples/python/dask_campaign.py --scheduler tcp://10.0.0.5:8786
  .venv/bin/python examples/python/dask_campaign.py --small --compare     # small grid, and the same
                                                                          # tasks in this process
"""
import argparse
import hashlib
import itertools
import json
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
FMU = ROOT / "target" / "fmu" / "ThermoVIA.fmu"
ZERO_CELSIUS = 273.15


def grid(small):
    """The campaign's points: (pcl °C, motor Hz, load torque N·m, link inertia kg·m²)."""
    if small:
        return list(itertools.product([22.0, 60.0], [0.5, 1.0], [0.0, 0.2], [0.018]))
    return list(itertools.product([22.0, 40.0, 50.0, 60.0], [0.5, 1.0, 2.0], [0.0, 0.1, 0.2], [0.012, 0.018, 0.024]))


_UNPACKED = {}


def unpacked_fmu(fmu_bytes):
    """This process's unpacked copy of the FMU (once per worker, keyed by content)."""
    from fmpy import extract

    key = hashlib.sha256(fmu_bytes).hexdigest()[:16]
    if key not in _UNPACKED:
        folder = Path(tempfile.gettempdir()) / f"thermovia-dask-{os.getpid()}-{key}"
        archive = folder.with_suffix(".fmu")
        folder.mkdir(parents=True, exist_ok=True)
        archive.write_bytes(fmu_bytes)
        _UNPACKED[key] = extract(str(archive), unzipdir=str(folder))
    return _UNPACKED[key]


def simulate_point(fmu_bytes, point, cycles=6, step=1e-3):
    """One grid point: the motor follows a sine (prescribed angle), the PCL starts and stays warm
    (no heater, short run), a constant load acts on the link."""
    from fmpy import simulate_fmu

    temp_c, freq, load, inertia = point
    amp, w = 0.3, 2 * math.pi * freq
    stop = cycles / freq
    t = np.arange(int(round(stop / step)) + 1) * step
    tk = temp_c + ZERO_CELSIUS
    const = np.full_like(t, 1.0)
    columns = {"motor_angle_command": amp * np.sin(w * t), "motor_speed_command": amp * w * np.cos(w * t),
               "load_torque": load * const, "heater_power": 0 * const, "motor_torque": 0 * const,
               "ambient_temperature": tk * const, "housing_temperature_command": tk * const}
    signals = np.array(list(zip(t, *columns.values())), dtype=[("time", "f8")] + [(n, "f8") for n in columns])
    result = simulate_fmu(unpacked_fmu(fmu_bytes), stop_time=stop, step_size=step, output_interval=step,
                          input=signals, output=["link_angle", "transmitted_torque"],
                          start_values={"motor_drive": 1, "link_inertia": inertia, "initial_pcl_temperature": tk,
                                        "initial_housing_temperature": tk, "ambient_temperature": tk,
                                        "excitation_frequency": freq})
    # the last two whole cycles, first harmonic of the link against the motor
    sel = result["time"] >= stop - 2 / freq - 1e-9
    tt, link = result["time"][sel][:-1], result["link_angle"][sel][:-1]
    c = 2 * np.mean((link - link.mean()) * np.exp(-1j * w * tt))
    return {"temperature_c": temp_c, "frequency_hz": freq, "load_nm": load, "link_inertia": inertia,
            "amplitude_ratio": float(abs(c) / amp), "phase_deg": float(np.degrees(np.angle(c / -1j))),
            "peak_torque_nm": float(np.max(np.abs(result["transmitted_torque"])))}


def run_campaign(client, points, fmu_data):
    """`fmu_data`: the FMU's bytes, scattered to the workers once for every campaign."""
    futures = client.map(simulate_point, [fmu_data] * len(points), points, pure=False)
    return client.gather(futures)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fmu", type=Path, default=FMU, help="the packaged FMU [target/fmu/ThermoVIA.fmu]")
    ap.add_argument("--scheduler", help="address of a running Dask scheduler (default: a LocalCluster)")
    ap.add_argument("--workers", type=int, default=os.cpu_count(), help="LocalCluster workers (one thread each)")
    ap.add_argument("--small", action="store_true", help="8 points instead of 108 (for CI)")
    ap.add_argument("--compare", action="store_true", help="also run the tasks in this process, one after another")
    ap.add_argument("--out", type=Path, help="write the results and timings as JSON here")
    a = ap.parse_args(argv)
    from distributed import Client, LocalCluster

    if not a.fmu.is_file():
        ap.error(f"{a.fmu}: no such FMU (build it: cargo run --release -p fmu-build)")
    fmu_bytes = a.fmu.read_bytes()
    points = grid(a.small)
    report = {"points": len(points)}
    if a.scheduler:
        client = Client(a.scheduler)
        cores = sum(w["nthreads"] for w in client.scheduler_info()["workers"].values())
    else:
        cluster = LocalCluster(n_workers=a.workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client, cores = Client(cluster), a.workers
    with client:
        fmu_data = client.scatter(fmu_bytes, broadcast=True)
        run_campaign(client, points[:cores], fmu_data)  # warm-up: every worker unpacks the FMU once
        t0 = time.perf_counter()
        results = run_campaign(client, points, fmu_data)
        seconds = time.perf_counter() - t0
    report.update(results=results, dask_seconds=seconds, cores=cores,
                  tasks_per_second_per_core=len(points) / seconds / cores)
    print(f"dask: {len(points)} tasks on {cores} cores in {seconds:.2f} s "
          f"({report['tasks_per_second_per_core']:.2f} tasks/s per core)")
    if a.compare:
        simulate_point(fmu_bytes, points[0])  # same warm-up
        t0 = time.perf_counter()
        serial = [simulate_point(fmu_bytes, p) for p in points]
        report["serial_seconds"] = time.perf_counter() - t0
        report["serial_tasks_per_second"] = len(points) / report["serial_seconds"]
        report["serial_matches"] = serial == results
        print(f"one process: {report['serial_seconds']:.2f} s ({report['serial_tasks_per_second']:.2f} tasks/s); "
              f"per-core efficiency {report['tasks_per_second_per_core'] / report['serial_tasks_per_second']:.2f}; "
              f"results identical: {report['serial_matches']}")
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(report, indent=2) + "\n")
    return report


if __name__ == "__main__":
    main()
