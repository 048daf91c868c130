//! Measured data → fit → residual → missing effect → refit (issue 4).
//!
//! `data` reads runs (interfaces.md), `sim` drives the packaged FMU through the harness, `fit` is
//! Levenberg–Marquardt through those simulations, `diagnose` analyses residuals and ranks the
//! effect library, `search` adds and refits, `report` writes report.json, Markdown and plots,
//! `synth` writes synthetic measured runs from a truth model, `paper` runs the loop on the
//! paper's summary numbers.

pub mod data;
pub mod diagnose;
pub mod drive;
pub mod fit;
pub mod paper;
pub mod reference;
pub mod report;
pub mod search;
pub mod signal;
pub mod stepwise;
pub mod sim;
pub mod synthetic;

use signal::{rms_frequency, savitzky_golay, second_difference_noise};
pub use synthetic::SynthArgs;

/// `thermovia calibrate` options.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[cfg_attr(
    feature = "cli",
    command(after_long_help = "Examples:
  # runs of the device (the measured motor angle drives the model; the link angle is predicted)
  thermovia synth --out out/synth --coulomb-friction 0.03
  thermovia calibrate out/synth --out out/calibrate

  # a real drive log, closed loop: the reference is replayed through the rig's controller
  # (declared in the file: # drive=reference, # controller_kp=..., # axis=linear, # transmission=rigid)
  thermovia calibrate data/emps/emps_estimation.csv --validate data/emps/emps_validation.csv \\
      --published data/emps/published.json --out out/emps

  # a log driven by its measured torque (# drive=motor_torque): motor and link angles are predicted
  thermovia calibrate runs/torque_driven.csv --out out/torque

File format, metadata and report keys: docs/interfaces.md (\"Measured data\", \"Runs from other rigs and drives\").")
)]
pub struct CalibrateArgs {
    /// Run files (CSV, docs: interfaces.md) or folders of them.
    pub inputs: Vec<std::path::PathBuf>,
    /// Held-out runs (a file or folder; repeat the option for more): simulated with the parameters
    /// fitted on INPUTS and reported under "validation". For drive runs (`# drive=motor_torque` or
    /// `reference`) they are only scored, never used to choose an effect or a load gain.
    #[cfg_attr(feature = "cli", arg(long, value_name = "FILE_OR_DIR"))]
    pub validate: Vec<std::path::PathBuf>,
    /// A published reference to compare with (JSON: {"parameters": {"inertia": …, "viscous_friction": …,
    /// "coulomb_friction": …, "offset": …}, "position_relerr_percent": {"estimation": …, "validation": …}});
    /// never used by the fit. Its parameters are simulated by this loop on the same runs
    /// ("published_same_simulation"): the figures to compare with, since printed ones may come from
    /// another simulation of the same model.
    #[cfg_attr(feature = "cli", arg(long, value_name = "FILE"))]
    pub published: Option<std::path::PathBuf>,
    /// Folder for report.json, the Markdown report and plots (written atomically).
    #[cfg_attr(feature = "cli", arg(long, default_value = "out/calibrate"))]
    pub out: std::path::PathBuf,
    /// Packaged FMU to use (default target/fmu/ThermoVIA.fmu).
    #[cfg_attr(feature = "cli", arg(long))]
    pub fmu: Option<std::path::PathBuf>,
    /// FMU instances simulating in parallel (the default is this machine's core count).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = std::thread::available_parallelism().map_or(2, |n| n.get())))]
    pub threads: usize,
    /// Half-width in seconds of the zero-phase Savitzky–Golay smoothing of the measured motor angle
    /// before it drives the model; 0 uses the raw samples. Default: per run, 0.1 s over the
    /// highest frequency it carries (a quintic window that passes it flat while it averages the
    /// encoder steps), and off when the motor angle carries no noise.
    #[cfg_attr(feature = "cli", arg(long, value_name = "SECONDS"))]
    pub input_smoothing: Option<f64>,
    /// Run the loop on the paper's summary numbers instead of run files: writes paper.json and
    /// paper.md into --out. Without FILE, the repository's data/paper-reported.json (built in).
    #[cfg_attr(feature = "cli", arg(long, value_name = "FILE", num_args = 0..=1))]
    pub paper: Option<Option<std::path::PathBuf>>,
    /// Skip the SVG plots (report.json and report.md only).
    #[cfg_attr(feature = "cli", arg(long))]
    pub no_plots: bool,
    /// Seconds the effect search may take (device runs). When it runs out, the search stops
    /// between refits, keeps the best model found and says so in the report (`search_budget`).
    #[cfg_attr(feature = "cli", arg(long, value_name = "SECONDS", default_value_t = 300.0))]
    pub search_budget: f64,
}

#[cfg(feature = "cli")]
#[derive(clap::Parser)]
struct CalibrateCli {
    #[cfg_attr(feature = "cli", command(flatten))]
    args: CalibrateArgs,
}

#[cfg(feature = "cli")]
impl CalibrateArgs {
    /// Options as `thermovia calibrate` would read them from `args` (without the program name).
    pub fn from_cli(args: &[&str]) -> Result<CalibrateArgs, clap::Error> {
        use clap::Parser;
        CalibrateCli::try_parse_from(std::iter::once("calibrate").chain(args.iter().copied())).map(|c| c.args)
    }
}

/// The fitted temperature group each held-out run uses: the one nearest its own temperature
/// (held-out runs take the moduli fitted there; nothing is fitted on them).
fn held_out_groups(held: &[data::Run], fitted_temperatures: &[f64]) -> Vec<usize> {
    let (group, temperatures) = group_runs(held);
    let nearest = |t: f64| {
        (0..fitted_temperatures.len())
            .min_by(|&a, &b| (fitted_temperatures[a] - t).abs().total_cmp(&(fitted_temperatures[b] - t).abs()))
            .unwrap_or(0)
    };
    group.into_iter().map(|g| nearest(temperatures[g])).collect()
}

/// Temperature groups: runs at one nominal temperature share E' and E''. The nominal temperature is
/// the declared `temperature_c` metadata, else the thermocouple mean, to 0.5 °C.
pub fn group_runs(runs: &[data::Run]) -> (Vec<usize>, Vec<f64>) {
    let mut temps: Vec<f64> = Vec::new();
    let mut group = Vec::new();
    for r in runs {
        let t = r.meta_f64("temperature_c").unwrap_or_else(|| r.mean_temperature_c());
        let t = (t * 2.0).round() / 2.0;
        let g = match temps.iter().position(|&x| x == t) {
            Some(g) => g,
            None => {
                temps.push(t);
                temps.len() - 1
            }
        };
        group.push(g);
    }
    (group, temps)
}

/// Half-width in samples of the motor angle's smoothing (`seconds`: given, or None for the
/// default): 0.1 s over the highest frequency the run carries, its own for a single sinusoid, else
/// three times its RMS frequency rms(θm')/(2π rms(θm − mean)), with speeds over ±10 ms. A quintic
/// Savitzky–Golay window of M samples passes up to about fs/M (Schafer 2011), ten times that
/// frequency. A motor angle without noise (second-difference noise below 1e-12 of its swing) is
/// not smoothed.
pub fn smoothing_half_width(r: &data::Run, seconds: Option<f64>) -> usize {
    let n = r.time.len();
    let dt = (r.time[n - 1] - r.time[0]) / (n - 1).max(1) as f64;
    let seconds = match seconds {
        Some(s) => s,
        None => {
            let swing = r.motor.iter().fold(0.0f64, |a, &b| a.max(b.abs())).max(1e-300);
            if second_difference_noise(&r.motor) <= 1e-12 * swing {
                return 0;
            }
            let top = if fit::is_sinusoidal_signal(&r.time, &r.motor, r.frequency_hz) {
                r.frequency_hz
            } else {
                3.0 * rms_frequency(&r.time, &r.motor)
            };
            if top > 0.0 {
                0.1 / top
            } else {
                0.0
            }
        }
    };
    ((seconds / dt).round() as usize).min(n / 4)
}

/// The model's inputs from a measured run. The motor angle is smoothed (`smoothing_half_width`)
/// because it sets the commanded speed of every step: encoder steps of 2π/10000 at 1 kHz make the
/// raw slope jitter by ~0.6 rad/s, which the PCL damper (C = E''κr_p²/ω, ~20 N·m·s/rad at 40 °C
/// and 0.5 Hz) passes to the link as torque noise, and which a never-pulling backlash contact
/// rectifies into bias.
pub fn sim_input(r: &data::Run, smoothing_seconds: Option<f64>) -> sim::SimInput {
    sim::SimInput {
        time: r.time.clone(),
        motor: savitzky_golay(&r.motor, smoothing_half_width(r, smoothing_seconds)),
        housing_k: r.temperature_c.iter().map(|t| t + crate::report::ZERO_CELSIUS).collect(),
        frequency_hz: r.frequency_hz,
        link_inertia: r.link_inertia,
        link0: r.link[0],
        com_distance: r.meta_f64("link_length_m").unwrap_or(0.14),
        initial_link_speed: initial_speed(&r.time, &r.link),
    }
}

/// Speed at the first sample when the data show one (a run need not start at rest): the slope of a
/// least-squares quadratic over the first 20 ms (at least 10 samples), kept only when it stands
/// out of its own standard error by 3 (at rest, encoder noise alone must not set the link moving).
/// A link that starts at rest and catches up with the motor within a millisecond looks the same
/// over 20 ms, so `search::resolve_initial_speeds` lets the baseline fit decide.
pub fn initial_speed(t: &[f64], x: &[f64]) -> f64 {
    if std::env::var_os("THERMOVIA_NO_V0").is_some() {
        return 0.0;
    }
    let n = t.iter().take_while(|&&ti| ti - t[0] <= 0.02).count().max(10).min(t.len());
    if n < 4 {
        return 0.0;
    }
    let Some((v, se)) = signal::start_slope(t, x, n) else { return 0.0 };
    if v.abs() > 3.0 * se {
        v
    } else {
        0.0
    }
}

/// Everything `thermovia calibrate` computes, before it is written.
pub struct Calibration {
    pub runs: Vec<data::Run>,
    pub temperatures: Vec<f64>,
    /// The device loop (runs driven by the measured motor angle).
    pub outcome: Option<search::Outcome>,
    /// The drive loop (`drive=motor_torque` or `reference`, rigid or linear axes).
    pub drive: Option<drive::DriveOutcome>,
    pub report: serde_json::Value,
    pub files: Vec<(String, Vec<u8>)>,
}

/// Reads the runs, fits, diagnoses, searches the effect library and builds the report files.
pub fn calibrate(args: &CalibrateArgs) -> Result<Calibration, Box<dyn std::error::Error>> {
    let t0 = std::time::Instant::now();
    let runs = data::read_inputs(&args.inputs)?;
    let is_drive = |r: &data::Run| r.drive != data::DriveKind::MotorAngle || r.rigid;
    if runs.iter().any(is_drive) {
        return calibrate_drive(args, runs, t0);
    }
    if let Some(r) = runs.iter().find(|r| r.axis == data::Axis::Linear) {
        return Err(format!(
            "{}: axis=linear with drive=motor_angle is not supported (the device loop fits PCL moduli of a \
             rotary joint); declare `# drive=motor_torque` or `# drive=reference`",
            r.file.display()
        )
        .into());
    }
    let held = if args.validate.is_empty() { Vec::new() } else { data::read_inputs(&args.validate)? };
    if let Some(r) = held.iter().find(|r| is_drive(r) || r.axis == data::Axis::Linear) {
        return Err(format!(
            "{}: a held-out drive run (drive={}, axis={}) cannot validate runs driven by the measured motor angle",
            r.file.display(),
            r.drive.name(),
            r.axis.name()
        )
        .into());
    }
    let fmu = crate::open_fmu(args.fmu.as_deref())?;
    let sim = sim::Simulator::new(fmu, args.threads)?;
    let (group, temperatures) = group_runs(&runs);
    let inputs: Vec<sim::SimInput> = runs.iter().map(|r| sim_input(r, args.input_smoothing)).collect();
    let measured = runs.iter().map(|r| r.link.clone()).collect();
    let mut prob = fit::Problem::new(&sim, inputs, measured, group, &temperatures)?;
    let laws = damping_laws(&prob);
    // the black-box references need no FMU: computed beside the search
    let groups = prob.group.clone();
    let (outcome, references) = std::thread::scope(|scope| {
        let refs = scope.spawn(|| black_box_references(&runs, &groups));
        let budget = search::Budget::seconds(args.search_budget);
        (search::calibrate(&mut prob, &laws, &budget), refs.join())
    });
    let mut outcome = outcome?;
    search::debug(format_args!("search and reference: {:?}", t0.elapsed()));
    let references = references.map_err(|_| "the black-box reference panicked")?;
    let mut notes: Vec<String> = Vec::new();
    let held_prob = (!held.is_empty()).then(|| {
        prob.held_out(
            held.iter().map(|r| sim_input(r, args.input_smoothing)).collect(),
            held.iter().map(|r| r.link.clone()).collect(),
            held_out_groups(&held, &temperatures),
        )
    });
    // One frequency per temperature cannot tell viscous from hysteretic damping (identical fits,
    // identical in-sample predictions). Held-out runs at other frequencies can, but they judge the
    // model and never choose it: their verdict is reported, the law stays viscous.
    if let Some(h) = held_prob.as_ref().filter(|h| laws.undecided && h.sinusoidal().iter().all(|&s| s)) {
        let mut other = outcome.final_fit.spec.clone();
        other.law = fit::DampingLaw::Hysteretic;
        let sse = |spec: &fit::ModelSpec| {
            h.outputs(spec, &outcome.final_fit.p).map_or(f64::INFINITY, |o| h.residual(&o).iter().map(|e| e * e).sum())
        };
        let (v, hy) = (sse(&outcome.final_fit.spec), sse(&other));
        notes.push(format!(
            "the fitting runs have one frequency per temperature, so the damping law cannot be chosen from them; the \
             held-out runs judge it (SSE viscous {v:.4e}, hysteretic {hy:.4e}: they favour {}), but do not choose it: \
             add runs at a second frequency to the fitting set",
            if hy < v { "hysteretic" } else { "viscous" }
        ));
    }
    // The held-out check that may drop the added effects (issue 10, item 5) is a blocked fold on
    // the fitting runs (fitted on the first half of every run, scored on the second); --validate
    // runs are only scored.
    let (held_base, held_final) =
        (blocked_fold_rmse(&prob, &outcome.baseline)?, blocked_fold_rmse(&prob, &outcome.final_fit)?);
    let method = "a blocked fold: refitted on the first half of every run, scored on the second half (the --validate runs, if any, are scored under validation and choose nothing)";
    search::debug(format_args!("held-out: {:?}", t0.elapsed()));
    let reverted = !outcome.final_fit.spec.effects.is_empty() && held_final >= held_base;
    if reverted {
        notes.push(format!(
            "the added effects ({}) did not lower the held-out error ({held_base:.4e} → {held_final:.4e} rad): they were \
             dropped, and the final model is the baseline",
            outcome.final_fit.spec.effects.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ")
        ));
        outcome.final_fit = outcome.baseline.clone();
        outcome.final_signatures = outcome.baseline_signatures.clone();
        outcome.unexplained = !outcome.final_signatures.white();
    }
    let seconds = t0.elapsed().as_secs_f64();
    let mut report = report::report_json(&runs, &prob, &outcome, &temperatures, seconds);
    for (j, r) in report["runs"].as_array_mut().into_iter().flatten().zip(&runs) {
        let n = r.time.len();
        let dt = (r.time[n - 1] - r.time[0]) / (n - 1).max(1) as f64;
        j["input_smoothing_s"] = serde_json::json!(smoothing_half_width(r, args.input_smoothing) as f64 * dt);
        j["inertia_declared"] = serde_json::json!(r.link_inertia.is_some());
    }
    // "unexplained" against a flexible reference, not only white noise (issue 10, item 6)
    let floor = outcome.final_signatures.noise_floor;
    let excess = |x: f64| (x * x - floor * floor).max(0.0).sqrt();
    let model_rmse = outcome.final_fit.rmse();
    let (trivial, arx) = &references;
    let box_beats_model = excess(model_rmse) > REFERENCE_MARGIN * excess(arx.rmse);
    let leftover = outcome.final_signatures.leftover_harmonics(&prob.lengths(), prob.sinusoidal());
    search::debug(format_args!("leftover harmonics over noise: {leftover:?}"));
    let harmonics_left = leftover.is_some_and(|r| r > diagnose::NONLINEAR_HARMONIC_LIMIT);
    outcome.unexplained = !outcome.final_signatures.white() && (box_beats_model || harmonics_left);
    report["unexplained"] = serde_json::json!(outcome.unexplained);
    report["residual_white"] = serde_json::json!(outcome.final_signatures.white());
    report["reference"] = serde_json::json!({
        "link_equals_motor": {"rmse_rad": trivial.rmse},
        "linear_black_box": {"rmse_rad": arx.rmse, "order": [arx.order.0, arx.order.1], "per_run_rmse_rad": arx.per_run_rmse,
            "what": "a discrete-time linear model from motor angle to link angle per temperature, free-run (simulated) error, order chosen on held-out halves"},
        "explained_share": reference::explained_share(trivial.rmse, model_rmse, arx.rmse, floor),
        "words": reference::words(model_rmse, trivial.rmse, arx, floor),
        "nonlinear": {"leftover_harmonics_over_noise": leftover, "limit": diagnose::NONLINEAR_HARMONIC_LIMIT,
            "what": "the largest residual harmonic at 2ω, 3ω or 5ω over what white noise at the floor leaves (σ √(2/N)), median over the sinusoidal runs: a nonlinearity the model lacks, in the library or not"},
        "rule": format!("unexplained when the residual is not white (structure ratio ≥ {}) and either the black box's rms above the noise floor is below the model's by more than a factor {REFERENCE_MARGIN}, or harmonics at 2ω, 3ω or 5ω are left above {} times the noise's", diagnose::STRUCTURE_LIMIT, diagnose::NONLINEAR_HARMONIC_LIMIT),
    });
    if !outcome.unexplained && !outcome.final_signatures.white() {
        report["remaining_structure"] = serde_json::json!(format!(
            "{} — but a linear black box explains no more of it than the model, and no harmonic of the excitation is left above the noise's",
            report::remaining_structure(&outcome.final_signatures)
        ));
    }
    report["held_out"] = serde_json::json!({
        "method": method,
        "baseline_rmse_rad": held_base,
        "final_rmse_rad": if reverted { held_base } else { held_final },
        "effects_reverted": reverted,
        "notes": notes,
    });
    if let Some(h) = &held_prob {
        let sim_of = |f: &fit::Fit| h.outputs(&f.spec, &f.p).ok_or("the FMU could not simulate a held-out run");
        let (b, f) = (sim_of(&outcome.baseline)?, sim_of(&outcome.final_fit)?);
        report["validation"] = serde_json::json!({
            "runs": held.iter().map(|r| serde_json::json!({"file": r.name(), "temperature_c": r.mean_temperature_c(),
                "frequency_hz": r.frequency_hz, "samples": r.time.len()})).collect::<Vec<_>>(),
            "baseline": report::held_out_metrics(&h.measured, &b),
            "final": report::held_out_metrics(&h.measured, &f),
        });
    }
    report["warnings"] = serde_json::json!(device_warnings(&runs, &report));
    let mut files = vec![
        ("report.json".to_string(), (serde_json::to_string_pretty(&report)? + "\n").into_bytes()),
        ("report.md".to_string(), report::report_markdown(&report, &outcome).into_bytes()),
    ];
    if !args.no_plots {
        files.extend(report::plots(&runs, &prob, &outcome)?);
        files.push(("plots/identified.svg".to_string(), report::identified_plot(&report)?.into_bytes()));
    }
    Ok(Calibration { runs, temperatures, outcome: Some(outcome), drive: None, report, files })
}

/// The black box must beat the model's rms above the noise by this factor for the leftover
/// structure to count as unexplained (a margin for the reference's own fitting freedom).
const REFERENCE_MARGIN: f64 = 1.1;

/// Link = motor and a linear black box per temperature group (reference.rs), on the measured runs.
fn black_box_references(runs: &[data::Run], group: &[usize]) -> (reference::Reference, reference::Reference) {
    let signals: Vec<reference::RunSignals> =
        runs.iter().map(|r| reference::RunSignals { time: &r.time, motor: &r.motor, link: &r.link }).collect();
    let t = std::time::Instant::now();
    let out = (reference::trivial(&signals), reference::arx_grouped(&signals, group, BLACK_BOX_MAX_ORDER));
    search::debug(format_args!("black box: {:?}", t.elapsed()));
    out
}

/// Highest order of the black box: two modes (motor–link resonance and one more) are what a
/// transmission with a link shows; more fits noise on records this long.
const BLACK_BOX_MAX_ORDER: usize = 4;

/// RMSE on the second half of every run of the model refitted (from `fit`) on the first halves:
/// a blocked fold that respects time (the second half is predicted by simulating on from the
/// start, never fitted).
fn blocked_fold_rmse(prob: &fit::Problem, fit: &fit::Fit) -> Result<f64, String> {
    let first = prob.truncated(0.5);
    let refit = fit::levenberg_marquardt(&first, fit.spec.clone(), fit.p.clone(), search::MAX_ITERATIONS)?;
    let out = prob.outputs(&refit.spec, &refit.p).ok_or("the FMU could not simulate the blocked fold")?;
    let (mut sse, mut n) = (0.0, 0usize);
    for (y, m) in prob.measured.iter().zip(&out) {
        for k in y.len() / 2..y.len() {
            sse += (y[k] - m[k]).powi(2);
            n += 1;
        }
    }
    Ok((sse / n.max(1) as f64).sqrt())
}

/// Frequencies closer than this (relative) are one frequency.
const SAME_FREQUENCY: f64 = 0.05;

/// The damping laws the data allow (issue 10, item 2). Runs that are not single sinusoids have no
/// "excitation frequency": viscous only. Sinusoidal runs at two or more frequencies within one
/// temperature tell the laws apart: both are fitted (baseline and after each added effect) and the
/// lower BIC wins. At one frequency per temperature they predict the same runs: viscous is kept
/// and the report says the data cannot tell.
fn damping_laws(prob: &fit::Problem) -> search::LawChoice {
    use fit::DampingLaw::{Hysteretic, Viscous};
    use fit::SpringBank::{Nominal, Scaled};
    let sinusoidal = prob.sinusoidal().iter().all(|&s| s);
    let two_frequencies = (0..prob.n_groups).any(|g| {
        let f: Vec<f64> =
            (0..prob.inputs.len()).filter(|&r| prob.group[r] == g).map(|r| prob.inputs[r].frequency_hz).collect();
        f.iter().any(|a| f.iter().any(|b| (a - b).abs() > SAME_FREQUENCY * a.max(*b)))
    });
    let (laws, reason) = if !sinusoidal {
        (vec![Viscous], "some runs are not single sinusoids, so no law that needs the excitation frequency applies")
    } else if !two_frequencies {
        (
            vec![Viscous],
            "every temperature has runs at one frequency only: viscous and hysteretic damping predict the same runs \
             and cannot be told apart (the damping is reported at that frequency)",
        )
    } else {
        (
            vec![Viscous, Hysteretic],
            "runs at two or more frequencies per temperature: both laws fitted, the lower BIC kept (baseline and after \
             each added effect)",
        )
    };
    let mut reason = reason.to_string();
    // the split of K between springs and PCL shows only while the temperature moves in a run
    let banks = if diagnose::thermocouple_varies(prob) {
        reason += "; the thermocouple moves within runs, so the spring bank is fitted two ways (scaled with the PCL, \
                   or nominal with the PCL carrying the rest) and the lower BIC kept";
        vec![Scaled, Nominal]
    } else {
        reason += "; the thermocouple is steady within runs, so the split of K between springs and PCL cannot show \
                   (springs scaled with the PCL)";
        vec![Scaled]
    };
    let allowed = laws.iter().flat_map(|&l| banks.iter().map(move |&b| (l, b))).collect();
    search::LawChoice { allowed, reason, undecided: sinusoidal && !two_frequencies }
}

/// What a reader of the device loop's numbers must know: an inertia taken from the FMU's default
/// rather than declared, and material factors stopped at their bounds. Never silent: report.json
/// `warnings`, report.md and the console.
fn device_warnings(runs: &[data::Run], report: &serde_json::Value) -> Vec<String> {
    let mut warnings = Vec::new();
    let from_mass: Vec<String> = runs.iter().filter(|r| r.inertia_from_mass).map(|r| r.name()).collect();
    if !from_mass.is_empty() {
        warnings.push(format!(
            "the link inertia of {} is the point mass m·l² from link_mass_kg and link_length_m (the link's own \
             inertia about its centre is not in it): declare link_inertia_kgm2 when it is known",
            from_mass.join(", ")
        ));
    }
    let undeclared: Vec<String> = runs.iter().filter(|r| r.link_inertia.is_none()).map(|r| r.name()).collect();
    if !undeclared.is_empty() {
        warnings.push(format!(
            "link_inertia_kgm2 is not declared in {} of {} runs ({}): the FMU's default link_inertia is used, so the \
             fitted stiffness and damping are known only relative to it (K/J and C/J); declare the inertia for \
             physical values",
            undeclared.len(),
            runs.len(),
            undeclared.join(", ")
        ));
    }
    for e in report["added_effects"].as_array().into_iter().flatten().filter(|e| e["at_plausible_limit"] == true) {
        warnings.push(format!(
            "{} sits at its plausible limit {} (its torque on the link at {}× the largest transmission plus inertial \
             torque the runs show, or a play twice the largest relative angle): the data cannot show it that large, \
             and it is likely standing in for an effect the library lacks",
            e["effect"].as_str().unwrap_or("?"),
            e["plausible_limits"],
            fit::PLAUSIBLE_TORQUE_FACTOR
        ));
    }
    for (stage, key) in [("baseline", "identified_baseline"), ("final", "identified")] {
        for g in report[key].as_array().into_iter().flatten() {
            if g["at_bound"].as_bool() == Some(true) {
                warnings.push(format!(
                "{stage} fit at {} °C: the transmission stopped at a bound (K = {:.4e} N·m/rad within {:.0e}–{:.2e}, C = \
                 {:.4e} N·m·s/rad within {:.0e}–{:.2e}; the upper ends are what the sample rate can show for this \
                 inertia): the structure cannot reach what these data want, and what the loop adds may be filling \
                 that gap",
                g["temperature_c"].as_f64().unwrap_or(f64::NAN),
                g["stiffness"].as_f64().unwrap_or(f64::NAN),
                g["stiffness_range"][0].as_f64().unwrap_or(f64::NAN),
                g["stiffness_range"][1].as_f64().unwrap_or(f64::NAN),
                g["damping"].as_f64().unwrap_or(f64::NAN),
                g["damping_range"][0].as_f64().unwrap_or(f64::NAN),
                g["damping_range"][1].as_f64().unwrap_or(f64::NAN),
            ));
            }
        }
    }
    warnings
}

/// The drive loop (drive.rs) on runs driven by torque or by a reference, rigid or linear.
fn calibrate_drive(
    args: &CalibrateArgs,
    runs: Vec<data::Run>,
    t0: std::time::Instant,
) -> Result<Calibration, Box<dyn std::error::Error>> {
    let held = if args.validate.is_empty() { Vec::new() } else { data::read_inputs(&args.validate)? };
    let all: Vec<&data::Run> = runs.iter().chain(&held).collect();
    let first = all[0];
    for r in &all {
        if r.axis != first.axis {
            return Err(format!(
                "{}: axis={} but {} is axis={}: one calibration speaks one set of units",
                r.file.display(),
                r.axis.name(),
                first.file.display(),
                first.axis.name()
            )
            .into());
        }
        if r.drive == data::DriveKind::MotorAngle {
            return Err(format!(
                "{}: drive=motor_angle cannot be calibrated together with torque- or reference-driven runs",
                r.file.display()
            )
            .into());
        }
    }
    let published = match &args.published {
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
            Some(serde_json::from_str::<serde_json::Value>(&text).map_err(|e| format!("{}: {e}", p.display()))?)
        }
        None => None,
    };
    let fmu = crate::open_fmu(args.fmu.as_deref())?;
    let sim = sim::Simulator::new(fmu, args.threads)?;
    let (group, temperatures) = group_runs(&runs);
    let mut prob = drive::DriveProblem::new(&sim, &runs, group, temperatures.len());
    let mut held_prob = if held.is_empty() {
        None
    } else {
        Some(drive::DriveProblem::new(&sim, &held, held_out_groups(&held, &temperatures), temperatures.len()))
    };
    let budget = stepwise::Budget::seconds(args.search_budget);
    let outcome = drive::calibrate(&mut prob, held_prob.as_mut(), &budget)?;
    let seconds = t0.elapsed().as_secs_f64();
    let mut report = drive::report_json(&runs, &prob, &outcome, &temperatures, published.as_ref(), seconds);
    if let Some(same) = published.as_ref().and_then(|p| drive::published_same_simulation(&prob, held_prob.as_ref(), p))
    {
        report["published_same_simulation"] = same;
    }
    let mut files = vec![
        ("report.json".to_string(), (serde_json::to_string_pretty(&report)? + "\n").into_bytes()),
        ("report.md".to_string(), drive::report_markdown(&report).into_bytes()),
    ];
    if !args.no_plots {
        files.extend(drive::plots(&prob, &outcome, runs[0].axis)?);
    }
    Ok(Calibration { runs, temperatures, outcome: None, drive: Some(outcome), report, files })
}

pub fn run(args: &CalibrateArgs) -> Result<(), Box<dyn std::error::Error>> {
    if let Some(path) = &args.paper {
        let (origin, text) = match path {
            Some(p) => {
                (p.display().to_string(), std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?)
            }
            None => ("data/paper-reported.json (built in)".to_string(), paper::REPORTED_JSON.to_string()),
        };
        let source: serde_json::Value = serde_json::from_str(&text).map_err(|e| format!("{origin}: {e}"))?;
        let fmu = crate::open_fmu(args.fmu.as_deref())?;
        let sim = sim::Simulator::new(fmu, args.threads)?;
        let (j, md) = paper::run(&sim, &source)?;
        let files = vec![
            ("paper.json".to_string(), (serde_json::to_string_pretty(&j)? + "\n").into_bytes()),
            ("paper.md".to_string(), md.clone().into_bytes()),
        ];
        synthetic::write_atomically(&args.out, &files)?;
        println!("{md}");
        return Ok(());
    }
    let c = calibrate(args)?;
    synthetic::write_atomically(&args.out, &c.files)?;
    if let Some(d) = &c.drive {
        let j = &c.report;
        let unit = j["units"]["position"].as_str().unwrap_or("");
        let m = |a: &serde_json::Value| a["relerr_percent"].as_f64().unwrap_or(f64::NAN);
        let added: Vec<&str> = d.final_fit.effects.iter().map(|e| e.name()).collect();
        let mut line = format!(
            "{} runs: position relerr baseline {:.4} %, final {:.4} % (RMSE {:.3e} → {:.3e} {unit})",
            c.runs.len(),
            m(&j["baseline"]),
            m(&j["final"]),
            j["baseline"]["rmse"].as_f64().unwrap_or(f64::NAN),
            j["final"]["rmse"].as_f64().unwrap_or(f64::NAN)
        );
        if j.get("validation").is_some() {
            line += &format!(
                "; validation {:.4} % → {:.4} %",
                m(&j["validation"]["baseline"]),
                m(&j["validation"]["final"])
            );
        }
        println!("{line}; added [{}]; report in {}", added.join(", "), args.out.display());
        return Ok(());
    }
    let outcome = c.outcome.as_ref().expect("device loop");
    for w in c.report["warnings"].as_array().into_iter().flatten() {
        eprintln!("thermovia: warning: {}", w.as_str().unwrap_or_default());
    }
    let m = |k: &str| c.report[k]["rmse_rad"].as_f64().unwrap_or(f64::NAN);
    let added: Vec<&str> = outcome.final_fit.spec.effects.iter().map(|e| e.name()).collect();
    println!(
        "{} runs: baseline RMSE {:.3e} rad, final {:.3e} rad, added [{}], unexplained {}; report in {}",
        c.runs.len(),
        m("baseline"),
        m("final"),
        added.join(", "),
        outcome.unexplained,
        args.out.display()
    );
    Ok(())
}

pub fn synth(args: &SynthArgs) -> Result<(), Box<dyn std::error::Error>> {
    synthetic::run(args)
}
