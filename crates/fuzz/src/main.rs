//! `thermovia-fuzz`: a fuzzing campaign against a packaged FMU (ThermoVIA's by default).
//!
//!   thermovia-fuzz [--calls N] [--seed S] [--jobs J] [--watchdog SECONDS] [FMU]
//!                                                               a campaign of about N FMI calls
//!   thermovia-fuzz --replay SEED OPS [FMU]                      one sequence's ops (comma list)
//!   thermovia-fuzz --life-cycles DIR N PER_LOAD                  N life cycles (the valgrind workload)
//!   thermovia-fuzz --resume DIR STATE STEPS H VRS                continue a serialized state here
//!
//! Exit status: 0 when no crash, hang or invariant violation was found, 1 otherwise.

#![forbid(unsafe_code)]

use std::path::PathBuf;

use thermovia_fuzz::{campaign, child_main, life_cycles, resume, Launcher, OPS_PER_SEQUENCE};
use thermovia_importer::Fmu;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("--child") => child_main(&PathBuf::from(args.get(1).expect("--child DIR"))),
        // --life-cycles DIR N PER_LOAD: the valgrind workload.
        Some("--life-cycles") => {
            let n = |i: usize| {
                args.get(i).and_then(|x| x.parse().ok()).unwrap_or_else(|| die("--life-cycles DIR N PER_LOAD"))
            };
            life_cycles(&PathBuf::from(&args[1]), n(2), n(3));
            println!("life cycles done");
            return;
        }
        // --resume DIR STATE_FILE STEPS H VR,VR,...: prints the outputs' bits, one per line.
        Some("--resume") => {
            let usage = || die("--resume DIR STATE_FILE STEPS H VRS");
            let (Some(dir), Some(file), Some(steps), Some(h), Some(vrs)) =
                (args.get(1), args.get(2), args.get(3), args.get(4), args.get(5))
            else {
                usage()
            };
            let bytes = std::fs::read(file).unwrap_or_else(|e| die(&format!("{file}: {e}")));
            let vrs: Vec<u32> = vrs.split(',').map(|v| v.parse().unwrap_or_else(|_| usage())).collect();
            let steps = steps.parse().unwrap_or_else(|_| usage());
            let h = h.parse().unwrap_or_else(|_| usage());
            match resume(&PathBuf::from(dir), &bytes, steps, h, &vrs) {
                Ok(values) => values.iter().for_each(|v| println!("{:016x}", v.to_bits())),
                Err(e) => die(&e),
            }
            return;
        }
        _ => {}
    }
    let mut calls: u64 = 1_000_000;
    let mut seed: u64 =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(1);
    let mut jobs = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let mut replay: Option<(u64, Vec<usize>)> = None;
    let mut watchdog = thermovia_fuzz::WATCHDOG;
    let mut fmu = PathBuf::from("target/fmu/ThermoVIA.fmu");
    let mut it = args.into_iter();
    let number = |x: Option<String>, what: &str| -> u64 {
        let x = x.unwrap_or_else(|| die(&format!("{what} needs a value")));
        let x = x.replace('_', "");
        x.parse::<u64>()
            .or_else(|_| x.parse::<f64>().map(|v| v as u64)) // 1e6
            .unwrap_or_else(|_| die(&format!("{what} {x:?}: not a number")))
    };
    while let Some(a) = it.next() {
        match a.as_str() {
            "--calls" => calls = number(it.next(), "--calls"),
            "--seed" => seed = number(it.next(), "--seed"),
            "--jobs" => jobs = number(it.next(), "--jobs").max(1) as usize,
            "--watchdog" => watchdog = std::time::Duration::from_secs(number(it.next(), "--watchdog").max(1)),
            "--replay" => {
                let s = number(it.next(), "--replay");
                let ops = it.next().unwrap_or_else(|| die("--replay SEED OPS"));
                let ops = if ops == "all" {
                    (0..OPS_PER_SEQUENCE).collect()
                } else {
                    ops.split(',').map(|o| o.parse().unwrap_or_else(|_| die(&format!("op {o:?}")))).collect()
                };
                replay = Some((s, ops));
            }
            "-h" | "--help" => {
                println!("usage: thermovia-fuzz [--calls N] [--seed S] [--jobs J] [--watchdog SECONDS] [FMU]\n       thermovia-fuzz --replay SEED OPS|all [FMU]");
                return;
            }
            other if other.starts_with('-') => die(&format!("unknown option {other}")),
            path => fmu = PathBuf::from(path),
        }
    }
    let opened = Fmu::open(&fmu).unwrap_or_else(|e| die(&e.to_string()));
    let launcher = Launcher {
        exe: std::env::current_exe().unwrap_or_else(|e| die(&e.to_string())),
        dir: opened.unpacked_dir().to_path_buf(),
        watchdog,
    };
    if let Some((s, ops)) = replay {
        let outcome = launcher.run(s, &ops);
        println!("sequence seed {s}, ops {ops:?}: {outcome:?}");
        std::process::exit(if outcome.kind() == "ok" { 0 } else { 1 });
    }
    println!("thermovia-fuzz: campaign seed {seed}, {calls} calls, {jobs} jobs, {}", fmu.display());
    let report = campaign(&launcher, seed, calls, jobs, true);
    print!("{report}");
    std::process::exit(if report.crashes + report.hangs + report.violations == 0 { 0 } else { 1 });
}

fn die(msg: &str) -> ! {
    eprintln!("thermovia-fuzz: {msg}");
    std::process::exit(2)
}
