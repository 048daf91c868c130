"""scripts/setup-system.sh decides what to install by the very file each build loads: bindgen loads
libclang.so or libclang-<ver>.so, and the image's libclang-cpp.so.14 is a different library."""
import os
import pathlib
import subprocess

SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "scripts" / "setup-system.sh"


def dry_run(tmp_path, *files):
    for f in files:
        (tmp_path / f).touch()
    env = dict(os.environ, SETUP_SYSTEM_LIBDIRS=str(tmp_path))
    env.pop("LIBCLANG_PATH", None)
    run = subprocess.run(["bash", str(SCRIPT), "--dry-run"], env=env, capture_output=True, text=True, check=True)
    return run.stdout


def test_libclang_cpp_alone_is_not_libclang(tmp_path):
    out = dry_run(tmp_path, "libclang-cpp.so.14", "libclang-cpp.so")
    assert "would install libclang-dev" in out, out
    assert "installed nothing" in out, out


def test_versioned_or_plain_libclang_is_enough(tmp_path):
    for name in ("libclang-14.so.1", "libclang.so"):
        d = tmp_path / name.replace(".", "_")
        d.mkdir()
        assert "libclang-dev" not in dry_run(d, name), name


def test_bad_argument_is_refused():
    run = subprocess.run(["bash", str(SCRIPT), "--install-everything"], capture_output=True, text=True)
    assert run.returncode == 2 and "--install-everything" in run.stderr, run.stderr


def test_valgrind_needs_its_memcheck_tool(tmp_path):
    """The launcher without memcheck-<arch>-linux (what the leak test runs) is not enough."""
    env = dict(os.environ, SETUP_SYSTEM_VALGRIND_DIRS=str(tmp_path))
    run = lambda: subprocess.run(["bash", str(SCRIPT), "--dry-run"], env=env, capture_output=True, text=True, check=True)
    assert "would install valgrind" in run().stdout
    (tmp_path / "memcheck-amd64-linux").touch()
    out = run().stdout
    if subprocess.run(["bash", "-c", "command -v valgrind"], capture_output=True).returncode == 0:
        # neither a reason to install it nor a place in the apt-get line
        assert "would install valgrind" not in out, out
        assert not any("apt-get install" in line and "valgrind" in line for line in out.splitlines()), out
