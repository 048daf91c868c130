//! Issue 13 in CI: a bounded fuzzing campaign (about 1e5 FMI calls, the seed printed), valgrind over
//! 1,000 life cycles with ten library unloads, and an FMU state carried from one process to another.
//! The long campaign: `cargo run --release -p thermovia-fuzz -- --calls 1e6`.

#[path = "../../../tests/common/mod.rs"]
mod common;

use std::path::PathBuf;
use std::process::Command;

use thermovia_fuzz::{campaign, Launcher};

const EXE: &str = env!("CARGO_BIN_EXE_thermovia-fuzz");

fn unpacked() -> (thermovia_importer::Fmu, PathBuf) {
    let fmu = common::fmu();
    let dir = fmu.unpacked_dir().to_path_buf();
    (fmu, dir)
}

#[test]
fn a_bounded_campaign_finds_no_crash_hang_or_violation() {
    let seed = std::env::var("THERMOVIA_FUZZ_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or_else(|| {
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(1)
    });
    println!("fuzz campaign seed {seed} (rerun: THERMOVIA_FUZZ_SEED={seed})");
    let (_fmu, dir) = unpacked();
    let launcher = Launcher { exe: PathBuf::from(EXE), dir, watchdog: thermovia_fuzz::WATCHDOG };
    let report = campaign(&launcher, seed, 100_000, 2, false);
    println!("{report}");
    assert!(report.calls >= 100_000, "{report}");
    assert_eq!(report.crashes + report.hangs + report.violations, 0, "seed {seed}:\n{report}");
}

/// Runs `args` under valgrind's memcheck; returns its report. Fails (never skips) without valgrind:
/// scripts/setup-system.sh installs it.
fn valgrind(args: &[&str]) -> (bool, String, String) {
    let out = Command::new("valgrind")
        .args(["--leak-check=full", "--show-leak-kinds=definite,indirect,possible", "--error-exitcode=9"])
        .arg(EXE)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("valgrind: {e} (scripts/setup-system.sh installs the Debian package valgrind)"));
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn lost_bytes(report: &str, kind: &str) -> u64 {
    let line = report.lines().find(|l| l.contains(kind)).unwrap_or_else(|| panic!("no {kind:?} in\n{report}"));
    let after = line.split(kind).nth(1).expect("a count");
    after.split_whitespace().next().expect("bytes").replace(',', "").parse().expect("a number")
}

#[test]
fn valgrind_a_thousand_life_cycles_lose_nothing() {
    let (_fmu, dir) = unpacked();
    let (ok, _, report) = valgrind(&["--life-cycles", dir.to_str().unwrap(), "1000", "100"]);
    let summary: Vec<&str> = report.lines().filter(|l| l.contains("lost:") || l.contains("ERROR SUMMARY")).collect();
    println!("{}", summary.join("\n"));
    assert!(ok, "valgrind found errors:\n{report}");
    for kind in ["definitely lost:", "indirectly lost:", "possibly lost:"] {
        assert_eq!(lost_bytes(&report, kind), 0, "{kind}\n{report}");
    }
    assert!(report.contains("ERROR SUMMARY: 0 errors"), "{report}");
}

#[test]
fn an_fmu_state_continues_bit_identically_in_another_process() {
    let (fmu, dir) = unpacked();
    let mut i = fmu.instantiate(None).unwrap();
    i.initialize(0.0, None, &[("coulomb_friction", 0.02), ("backlash_width", 0.01)]).unwrap();
    i.set("heater_power", 8.0).unwrap();
    i.set("motor_torque", 0.3).unwrap();
    let h = 1e-2;
    for _ in 0..50 {
        i.step(h).unwrap();
    }
    let saved = i.save_state().unwrap();
    let bytes = i.serialize_state(&saved).unwrap();
    let vrs: Vec<u32> = ["motor_angle", "link_angle", "pcl_temperature", "transmitted_torque"]
        .iter()
        .map(|n| fmu.variable(n).unwrap().value_reference)
        .collect();
    let mut here = Vec::new();
    for _ in 0..20 {
        i.step(h).unwrap();
        let mut v = vec![0.0; vrs.len()];
        i.get_reals(&vrs, &mut v).unwrap();
        here.extend(v.iter().map(|x| format!("{:016x}", x.to_bits())));
    }
    let file = std::env::temp_dir().join(format!("thermovia-state-{}.bin", std::process::id()));
    std::fs::write(&file, &bytes).unwrap();
    let vr_list = vrs.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(",");
    let args = ["--resume", dir.to_str().unwrap(), file.to_str().unwrap(), "20", "0.01", vr_list.as_str()];
    // The other process runs under valgrind: reading a state back touches no uninitialised memory.
    let (ok, stdout, report) = valgrind(&args);
    let _ = std::fs::remove_file(&file);
    assert!(ok, "{stdout}\n{report}");
    let there: Vec<String> = stdout.lines().map(str::to_string).collect();
    assert_eq!(here, there, "the resumed process diverged");
}
