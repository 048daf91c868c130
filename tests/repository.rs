//! The repository stands alone: a clone has no `../shared`, so no document or source refers
//! outside the repository, and every `docs/…` or `data/…` file that is named exists.

use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.is_dir() {
            files(&p, out);
        } else if matches!(p.extension().and_then(|e| e.to_str()), Some("rs" | "md" | "py" | "sh" | "toml")) {
            out.push(p);
        }
    }
}

fn sources() -> Vec<PathBuf> {
    let mut out = vec![Path::new(ROOT).join("README.md")];
    for d in ["src", "tests", "docs", "scripts", "benches", "examples", "fmu-build/src", ".ci"] {
        let dir = Path::new(ROOT).join(d);
        if dir.exists() {
            files(&dir, &mut out);
        }
    }
    out
}

#[test]
fn nothing_refers_outside_the_repository() {
    let this_file = Path::new(ROOT).join("tests/repository.rs");
    let needle = ["..", "/shared"].concat();
    let mut bad = Vec::new();
    for f in sources().into_iter().filter(|f| *f != this_file) {
        let text = std::fs::read_to_string(&f).unwrap();
        for (i, line) in text.lines().enumerate() {
            if line.contains(&needle) {
                bad.push(format!("{}:{}: {}", f.display(), i + 1, line.trim()));
            }
        }
    }
    assert!(bad.is_empty(), "references outside the repository:\n{}", bad.join("\n"));
}

#[test]
fn every_named_doc_and_data_file_exists() {
    let mut missing = Vec::new();
    let mut seen = 0;
    for f in sources() {
        let text = std::fs::read_to_string(&f).unwrap();
        for (i, line) in text.lines().enumerate() {
            for prefix in ["docs/", "data/"] {
                for (at, _) in line.match_indices(prefix) {
                    // a path starts the token: not part of a longer one (target/…/docs/…)
                    if at > 0 && !" `([\"'".contains(line.as_bytes()[at - 1] as char) {
                        continue;
                    }
                    let name: String =
                        line[at..].chars().take_while(|c| c.is_alphanumeric() || "/._-".contains(*c)).collect();
                    let name = name.trim_end_matches(['.', '/']);
                    if !name.contains('.') {
                        continue; // a folder or prose, not a file
                    }
                    seen += 1;
                    if !Path::new(ROOT).join(name).exists() {
                        missing.push(format!("{}:{}: {name}", f.display(), i + 1));
                    }
                }
            }
        }
    }
    assert!(seen >= 10, "the scan found only {seen} references: is it still reading the sources?");
    assert!(missing.is_empty(), "named but missing:\n{}", missing.join("\n"));
}

/// `cargo tree` of one package, normal dependencies only, as crate names.
fn dependencies(package: &str) -> Vec<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = std::process::Command::new(cargo)
        .args(["tree", "--offline", "-e", "normal", "--prefix", "none", "--format", "{p}", "-p", package])
        .current_dir(ROOT)
        .output()
        .expect("cargo tree runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_string)
        .collect()
}

#[test]
fn the_fmu_links_none_of_the_tools_dependencies() {
    let deps = dependencies("thermovia-fmu");
    assert!(deps.iter().any(|d| d == "thermovia-model"), "{deps:?}");
    for banned in ["clap", "plotters", "indicatif", "libloading", "zip", "thermovia-importer", "thermovia-tools"] {
        assert!(!deps.iter().any(|d| d == banned), "thermovia-fmu depends on {banned}: {deps:?}");
    }
}

#[test]
fn the_tools_reach_the_model_only_through_the_c_api() {
    let deps = dependencies("thermovia-tools");
    assert!(deps.iter().any(|d| d == "thermovia-importer"), "{deps:?}");
    for banned in ["thermovia-model", "thermovia-fmu", "clap", "indicatif"] {
        assert!(!deps.iter().any(|d| d == banned), "thermovia-tools depends on {banned}: {deps:?}");
    }
    let deps = dependencies("thermovia-importer");
    assert!(!deps.iter().any(|d| d == "thermovia-fmu" || d == "thermovia-model"), "{deps:?}");
}

#[test]
fn the_mujoco_plugin_stands_beside_the_fmu_on_the_model() {
    let deps = dependencies("thermovia-mujoco");
    for needed in ["thermovia-model", "thermovia-variables"] {
        assert!(deps.iter().any(|d| d == needed), "{deps:?}");
    }
    for banned in ["thermovia-fmu", "thermovia-fmi2", "thermovia-importer", "thermovia-tools", "clap", "libloading"] {
        assert!(!deps.iter().any(|d| d == banned), "thermovia-mujoco depends on {banned}: {deps:?}");
    }
    let deps = dependencies("thermovia-variables");
    assert!(!deps.iter().any(|d| d == "thermovia-fmi2" || d == "thermovia-fmu"), "{deps:?}");
}

/// A submission is refused whole past 256 MiB of diffs: one profiler dump committed by mistake
/// (perf.data, callgrind.out.*) sinks a session's work. Whatever a script can make again stays out;
/// the largest file kept is the EMPS validation log (1.4 MiB).
#[test]
fn no_tracked_file_is_large_or_a_profile_dump() {
    const LIMIT_BYTES: u64 = 2 << 20;
    let out = std::process::Command::new("git")
        .args(["ls-files", "-z"])
        .current_dir(ROOT)
        .output()
        .expect("git runs (CI works in a clone)");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let names: Vec<String> =
        out.stdout.split(|b| *b == 0).filter(|n| !n.is_empty()).map(|n| String::from_utf8_lossy(n).into()).collect();
    assert!(names.len() > 50, "git ls-files listed only {} files: is this the repository?", names.len());
    let mut bad = Vec::new();
    for name in &names {
        let base = name.rsplit('/').next().unwrap_or(name);
        let dump = ["perf.data", "callgrind.out.", "cachegrind.out.", "massif.out.", "vgcore."]
            .iter()
            .any(|p| base.starts_with(p))
            || base.ends_with(".profraw");
        // a file staged for removal is listed but absent: nothing to weigh
        let size = std::fs::metadata(Path::new(ROOT).join(name)).map(|m| m.len()).unwrap_or(0);
        if dump || size > LIMIT_BYTES {
            bad.push(format!("{name}: {size} bytes{}", if dump { ", a profiler's output" } else { "" }));
        }
    }
    assert!(bad.is_empty(), "tracked files that do not belong in the repository:\n{}", bad.join("\n"));
}
