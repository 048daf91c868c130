//! What every integration test shares: the packaged FMU, located and checked against the sources.
//! A test never runs on an FMU older than the code: after a physics edit it stops with the
//! command that repackages it.

#![allow(dead_code)] // each test binary uses its own part

use std::io::Read;
use std::path::PathBuf;

use thermovia_importer::Fmu;

/// The packaged FMU's path, after checking that it exists and was built from today's sources.
pub fn fmu_path() -> PathBuf {
    let path = fmu_build::fmu_path();
    let rebuild = "run `cargo run --release -p fmu-build` (scripts/test-all.sh does it first)";
    let file = std::fs::File::open(&path).unwrap_or_else(|e| panic!("{}: {e}: {rebuild}", path.display()));
    let mut zip =
        zip::ZipArchive::new(file).unwrap_or_else(|e| panic!("{}: not a zip archive ({e}): {rebuild}", path.display()));
    let mut packaged = String::new();
    zip.by_name(fmu_build::SOURCE_HASH_ENTRY)
        .unwrap_or_else(|_| {
            panic!("{} has no {}: it predates the check; {rebuild}", path.display(), fmu_build::SOURCE_HASH_ENTRY)
        })
        .read_to_string(&mut packaged)
        .expect("readable hash");
    let current = fmu_build::source_hash(&fmu_build::workspace_root()).expect("sources readable");
    assert_eq!(
        packaged.trim(),
        current,
        "{} is stale: it was built from other sources than the working tree's; {rebuild}",
        path.display()
    );
    path
}

/// The packaged FMU, opened (see [`fmu_path`]).
pub fn fmu() -> Fmu {
    Fmu::open(fmu_path()).expect("the packaged FMU opens")
}
