//! Generates the MuJoCo bindings from the pinned wheel's headers and links its libmujoco.
//!
//! The wheel is found at `$MUJOCO_DIR` or in the workspace's venv (`scripts/setup-python.sh` installs
//! the pinned `mujoco` there); nothing is downloaded. The library is linked by its full path, so the
//! plugin records the wheel's soname (libmujoco.so.<version>) and, loaded into a process that already
//! has that MuJoCo (Python's `mujoco`), shares its plugin registry.

use std::path::{Path, PathBuf};

fn main() {
    println!("cargo:rerun-if-env-changed=MUJOCO_DIR");
    let dir = mujoco_dir().unwrap_or_else(|why| {
        eprintln!("thermovia-mujoco: {why}");
        std::process::exit(1)
    });
    let include = dir.join("include");
    let header = include.join("mujoco").join("mujoco.h");
    let library = std::fs::read_dir(&dir)
        .ok()
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("libmujoco.so.")))
        .unwrap_or_else(|| {
            eprintln!("thermovia-mujoco: no libmujoco.so.<version> in {}", dir.display());
            std::process::exit(1)
        });
    println!("cargo:rerun-if-changed={}", header.display());
    println!("cargo:rerun-if-changed={}", library.display());
    println!("cargo:rustc-link-arg={}", library.display());
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());

    let bindings = bindgen::Builder::default()
        .header(header.to_string_lossy())
        .clang_arg(format!("-I{}", include.display()))
        .allowlist_type("mjModel|mjData|mjpPlugin|mjtInt.*|mjtIntegrator|mjtTrn|mjtJoint|mjtObj|mjtPluginCapabilityBit")
        .allowlist_function(
            "mjp_registerPlugin|mjp_defaultPlugin|mj_getPluginConfig|mju_warning|mj_name2id|mj_id2name|mj_version",
        )
        .allowlist_var("mjVERSION_HEADER")
        .rustified_enum("mjt(Integrator|Trn|Joint|Obj|PluginCapabilityBit)_")
        .layout_tests(false)
        .derive_default(false)
        .generate()
        .unwrap_or_else(|e| {
            eprintln!("thermovia-mujoco: bindgen on {}: {e}", header.display());
            std::process::exit(1)
        });
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    bindings.write_to_file(out.join("mujoco.rs")).expect("writing the bindings");
}

fn mujoco_dir() -> Result<PathBuf, String> {
    if let Ok(d) = std::env::var("MUJOCO_DIR") {
        let d = PathBuf::from(d);
        return if d.join("include/mujoco/mujoco.h").is_file() {
            Ok(d)
        } else {
            Err(format!("MUJOCO_DIR={} holds no include/mujoco/mujoco.h", d.display()))
        };
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let root = root.canonicalize().unwrap_or(root);
    let lib = root.join(".venv/lib");
    for entry in std::fs::read_dir(&lib).into_iter().flatten().flatten() {
        let d = entry.path().join("site-packages/mujoco");
        if d.join("include/mujoco/mujoco.h").is_file() {
            return Ok(d);
        }
    }
    Err(format!(
        "the pinned mujoco wheel was not found in {}: run scripts/setup-python.sh (it installs \
         tests/python/requirements.txt), or set MUJOCO_DIR to a directory with include/mujoco/mujoco.h \
         and libmujoco.so.<version>",
        lib.display()
    ))
}
