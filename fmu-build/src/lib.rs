//! What fmu-build and the tests share: where the workspace is, and a hash of the sources the
//! packaged FMU is built from, so a test can refuse an FMU older than the code it would test.

use std::path::{Path, PathBuf};

/// Where the hash is stored inside the `.fmu` archive.
pub const SOURCE_HASH_ENTRY: &str = "documentation/source-hash.txt";

/// The crates the FMU binary is compiled from: their `src/` and manifest (not their tests, benches
/// or examples, which go into no binary).
const CRATES: [&str; 4] = ["crates/fmi2", "crates/model", "crates/variables", "crates/fmu"];
/// The package the closure of locked dependencies starts from.
const FMU_PACKAGE: &str = "thermovia-fmu";
/// What writes the rest of the archive: modelDescription.xml and documentation/.
const PACKAGER: &str = "fmu-build/src/main.rs";

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
    } else if path.extension().is_some_and(|e| e == "rs" || e == "toml") {
        out.push(path.to_path_buf());
    }
    Ok(())
}

/// The `[[package]]` entries of a Cargo.lock that the FMU package depends on, transitively
/// (itself included), in file order: a dependency the tools alone use changes nothing here.
pub fn locked_closure(lock: &str) -> String {
    // (name, entry text, names it depends on)
    let mut packages: Vec<(String, String, Vec<String>)> = Vec::new();
    for block in lock.split("[[package]]").skip(1) {
        let name = block
            .lines()
            .find_map(|l| l.trim().strip_prefix("name = "))
            .map(|n| n.trim_matches('"').to_string())
            .unwrap_or_default();
        let deps = match block.find("dependencies = [") {
            Some(at) => block[at..]
                .lines()
                .skip(1)
                .take_while(|l| !l.trim_start().starts_with(']'))
                .filter_map(|l| l.trim().trim_matches(|c| c == '"' || c == ',').split(' ').next().map(String::from))
                .collect(),
            None => Vec::new(),
        };
        packages.push((name, block.to_string(), deps));
    }
    let mut wanted = std::collections::BTreeSet::from([FMU_PACKAGE.to_string()]);
    loop {
        let before = wanted.len();
        for (name, _, deps) in &packages {
            if wanted.contains(name) {
                wanted.extend(deps.iter().cloned());
            }
        }
        if wanted.len() == before {
            break;
        }
    }
    packages.into_iter().filter(|(n, _, _)| wanted.contains(n)).map(|(_, text, _)| text).collect()
}

/// The parts of the workspace manifest that shape the FMU's build: `[workspace.package]`, the
/// `[profile.*]` sections, and the `[workspace.dependencies]` lines of the FMU's dependencies.
pub fn manifest_for_fmu(manifest: &str, lock: &str) -> String {
    let closure = locked_closure(lock);
    let in_closure = |key: &str| closure.contains(&format!("name = \"{key}\""));
    let mut section = String::new();
    let mut out = String::new();
    for line in manifest.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            section = t.to_string();
        }
        let keep = section == "[workspace.package]"
            || section.starts_with("[profile")
            || (section == "[workspace.dependencies]"
                && t.split('=').next().map(str::trim).is_some_and(|k| !k.is_empty() && in_closure(k)));
        if keep {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// FNV-1a (64 bit) over exactly what goes into the FMU: the relative path and bytes of every source
/// file of the crates the binary is compiled from and of the packager, in path order, then the
/// locked versions of their dependencies and the workspace manifest's parts that shape the build.
/// A fingerprint, not a security measure.
pub fn source_hash(root: &Path) -> std::io::Result<String> {
    let mut files = Vec::new();
    for c in CRATES {
        collect(&root.join(c).join("src"), &mut files)?;
        collect(&root.join(c).join("Cargo.toml"), &mut files)?;
    }
    collect(&root.join(PACKAGER), &mut files)?;
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
    let read = |name: &str| {
        std::fs::read_to_string(root.join(name)).or_else(|e| match e.kind() {
            std::io::ErrorKind::NotFound => Ok(String::new()),
            _ => Err(e),
        })
    };
    let (lock, manifest) = (read("Cargo.lock")?, read("Cargo.toml")?);
    eat(locked_closure(&lock).as_bytes());
    eat(&[0]);
    eat(manifest_for_fmu(&manifest, &lock).as_bytes());
    Ok(format!("{h:016x}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const LOCK: &str = r#"
[[package]]
name = "nalgebra"
version = "0.33.2"

[[package]]
name = "plotters"
version = "0.3.7"

[[package]]
name = "thermovia-fmu"
version = "0.1.0"
dependencies = [
 "thermovia-model",
]

[[package]]
name = "thermovia-model"
version = "0.1.0"
dependencies = [
 "nalgebra",
]

[[package]]
name = "thermovia-tools"
version = "0.1.0"
dependencies = [
 "plotters",
]
"#;

    const MANIFEST: &str = "[workspace]\nmembers = []\n\n[workspace.dependencies]\nnalgebra = \"0.33\"\nplotters = \"0.3\"\n\n[package]\nname = \"thermovia\"\n\n[dependencies]\nclap = \"4\"\n\n[profile.release]\ndebug = false\n";

    #[test]
    fn the_lock_closure_holds_the_fmus_dependencies_only() {
        let c = locked_closure(LOCK);
        for n in ["thermovia-fmu", "thermovia-model", "nalgebra"] {
            assert!(c.contains(&format!("name = \"{n}\"")), "{n} missing: {c}");
        }
        for n in ["plotters", "thermovia-tools"] {
            assert!(!c.contains(&format!("name = \"{n}\"")), "{n} included: {c}");
        }
        let m = manifest_for_fmu(MANIFEST, LOCK);
        assert!(m.contains("nalgebra") && m.contains("[profile.release]") && m.contains("debug = false"), "{m}");
        assert!(!m.contains("plotters") && !m.contains("clap"), "{m}");
    }

    #[test]
    fn the_hash_follows_what_goes_into_the_fmu_and_nothing_else() {
        let root = std::env::temp_dir().join(format!("fmu-build-hash-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        for d in ["crates/model/src", "crates/model/tests", "crates/tools/src", "fmu-build/src"] {
            std::fs::create_dir_all(root.join(d)).unwrap();
        }
        let write = |f: &str, text: &str| std::fs::write(root.join(f), text).unwrap();
        write("crates/model/src/lib.rs", "pub const K: f64 = 1.0;");
        write("crates/model/tests/k.rs", "// a test");
        write("crates/tools/src/lib.rs", "// a tool");
        write("fmu-build/src/main.rs", "// the packager");
        write("Cargo.lock", LOCK);
        write("Cargo.toml", MANIFEST);
        let h0 = source_hash(&root).unwrap();
        let unchanged = [
            ("crates/tools/src/lib.rs", "// another tool".to_string()),
            ("crates/model/tests/k.rs", "// another test".to_string()),
            ("Cargo.lock", LOCK.replace("0.3.7", "0.3.8")),
            ("Cargo.toml", MANIFEST.replace("clap = \"4\"", "clap = \"4.5\"")),
        ];
        for (f, text) in unchanged {
            let before = std::fs::read_to_string(root.join(f)).unwrap();
            write(f, &text);
            assert_eq!(source_hash(&root).unwrap(), h0, "{f}: the tools' and tests' files are not in the FMU");
            write(f, &before);
        }
        let stale = [
            ("crates/model/src/lib.rs", "pub const K: f64 = 2.0;".to_string()),
            ("fmu-build/src/main.rs", "// another packager".to_string()),
            ("Cargo.lock", LOCK.replace("0.33.2", "0.33.3")),
            ("Cargo.toml", MANIFEST.replace("debug = false", "debug = true")),
        ];
        for (f, text) in stale {
            let before = std::fs::read_to_string(root.join(f)).unwrap();
            write(f, &text);
            assert_ne!(source_hash(&root).unwrap(), h0, "{f}: goes into the FMU, so an edit makes it stale");
            write(f, &before);
        }
        let _ = std::fs::remove_dir_all(&root);
    }
}
