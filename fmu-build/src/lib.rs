//! What fmu-build and the tests share: where the workspace is, and a hash of the sources the
//! packaged FMU is built from, so a test can refuse an FMU older than the code it would test.

use std::path::{Path, PathBuf};

/// Where the hash is stored inside the `.fmu` archive.
pub const SOURCE_HASH_ENTRY: &str = "documentation/source-hash.txt";

/// The folders and files whose content goes into the FMU binary and its description.
const SOURCES: [&str; 6] =
    ["crates/fmi2", "crates/model", "crates/fmu", "Cargo.lock", "Cargo.toml", "fmu-build/src/main.rs"];

pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("fmu-build sits in the workspace").to_path_buf()
}

/// The packaged FMU's path: `<workspace>/target/fmu/ThermoVIA.fmu`.
pub fn fmu_path() -> PathBuf {
    workspace_root().join("target").join("fmu").join("ThermoVIA.fmu")
}

fn collect(path: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    if !path.exists() {
        return Ok(());
    }
    if path.is_dir() {
        for entry in std::fs::read_dir(path)? {
            collect(&entry?.path(), out)?;
        }
    } else if path.extension().is_some_and(|e| e == "rs" || e == "toml" || e == "lock") {
        out.push(path.to_path_buf());
    }
    Ok(())
}

/// FNV-1a (64 bit) over the relative path and bytes of every source file, in path order: a
/// fingerprint, not a security measure.
pub fn source_hash(root: &Path) -> std::io::Result<String> {
    let mut files = Vec::new();
    for s in SOURCES {
        collect(&root.join(s), &mut files)?;
    }
    files.sort();
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            h = (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    for f in &files {
        eat(f.strip_prefix(root).unwrap_or(f).to_string_lossy().as_bytes());
        eat(&[0]);
        eat(&std::fs::read(f)?);
        eat(&[0]);
    }
    Ok(format!("{h:016x}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hash_follows_the_fmus_sources_and_nothing_else() {
        let root = std::env::temp_dir().join(format!("fmu-build-hash-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(root.join("crates/model/src")).unwrap();
        std::fs::create_dir_all(root.join("crates/tools/src")).unwrap();
        std::fs::write(root.join("crates/model/src/lib.rs"), "pub const K: f64 = 1.0;").unwrap();
        std::fs::write(root.join("crates/tools/src/lib.rs"), "// a tool").unwrap();
        let h0 = source_hash(&root).unwrap();
        std::fs::write(root.join("crates/tools/src/lib.rs"), "// another tool").unwrap();
        assert_eq!(source_hash(&root).unwrap(), h0, "the tools are not in the FMU");
        std::fs::write(root.join("crates/model/src/lib.rs"), "pub const K: f64 = 2.0;").unwrap();
        assert_ne!(source_hash(&root).unwrap(), h0, "a physics edit makes the FMU stale");
        let _ = std::fs::remove_dir_all(&root);
    }
}
