"""Shared pytest helpers for the Python checks of the packaged FMU.

make_container / container_fmu: ThermoVIA wrapped in an FMU Container built by fmu-manipulation-toolbox
(its compiled container importer runs ThermoVIA inside another FMI 2.0 Co-Simulation FMU). The container
is an FMU that is not ThermoVIA: modelIdentifier "ThermoVIAContainer", its own GUID, its own value
references (1..7 inputs, 8..21 outputs), a Real "time" variable with causality "independent", and the
embedded FMU under resources/00/. The toolbox is imported inside the function so that a missing package
fails the tests that use it, not the collection of every other test file.
"""
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FMU = ROOT / "target" / "fmu" / "ThermoVIA.fmu"
CONTAINER_STEP = 1e-3  # the container's internal fixed step; it calls ThermoVIA's doStep with exactly this h


def make_container(tmp_path, *, parameters=False) -> Path:
    """Build tmp_path/ThermoVIAContainer.fmu around a copy of target/fmu/ThermoVIA.fmu and return its path.

    The container exposes ThermoVIA's inputs and outputs under their own names. parameters=True also
    exposes its parameters as "thermovia.<name>" (the Enumerations become Integer parameters there).
    """
    from fmu_manipulation_toolbox.assembly import AssemblyNode

    assert FMU.exists(), "run `cargo run --release -p fmu-build` first"
    tmp_path = Path(tmp_path)
    tmp_path.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(FMU, tmp_path / FMU.name)
    node = AssemblyNode("ThermoVIAContainer.fmu", step_size=CONTAINER_STEP, auto_parameter=parameters)
    node.add_fmu(FMU.name)
    node.make_fmu(tmp_path)
    container = tmp_path / "ThermoVIAContainer.fmu"
    assert container.is_file(), f"fmu-manipulation-toolbox did not write {container}"
    return container


@pytest.fixture
def container_fmu(tmp_path) -> Path:
    """The container FMU (see make_container), built in this test's tmp_path."""
    return make_container(tmp_path)
