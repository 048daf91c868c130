//! `thermovia synth`: realistic measured runs from a truth model run through the FMU itself, with
//! chosen effects switched on and moduli away from the table. The paper's protocol: the motor
//! follows θ0 sin(2π f t) from rest, sampled at 1 kHz, at several temperatures and 0.5 / 1 Hz;
//! both encoders quantise to 2π/10000 (2500 ppr in quadrature, PAPER: Autonics E40S6-2500) after
//! Gaussian sensor noise. The truth is written to `truth.json` beside the runs, never into them.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::sim::{simulate, EffectValues, RunModel, SimInput, Simulator};
use thermovia_importer::Fmu;

/// Encoder resolution: 2500 lines × 4 edges per revolution [PAPER: E40S6-2500].
pub const ENCODER_QUANTUM: f64 = 2.0 * std::f64::consts::PI / 10000.0;

/// `thermovia synth` options.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SynthArgs {
    /// Folder to write the run files to (written atomically).
    #[cfg_attr(feature = "cli", arg(long, default_value = "out/synth"))]
    pub out: PathBuf,
    /// Run temperatures, °C (comma- or space-separated).
    #[cfg_attr(feature = "cli", arg(long, num_args = 1.., value_delimiter = ',', default_value = "22,40,50,60"))]
    pub temperatures: Vec<f64>,
    /// Motor frequencies, Hz (comma- or space-separated).
    #[cfg_attr(feature = "cli", arg(long, num_args = 1.., value_delimiter = ',', default_value = "0.5,1"))]
    pub frequencies: Vec<f64>,
    /// Length of each run, s.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 20.0))]
    pub duration: f64,
    /// Sampling rate, Hz.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1000.0))]
    pub rate: f64,
    /// Motor amplitude θ0, rad, as every angle of the command line.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.3))]
    pub amplitude_rad: f64,
    /// Standard deviation of the Gaussian sensor noise added before quantisation, rad.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1e-4))]
    pub noise_std: f64,
    /// Seed of the noise generator.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1))]
    pub seed: u64,
    /// Truth: factor on the table's E'.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.8))]
    pub storage_scale: f64,
    /// Truth: factor on the table's E''.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1.25))]
    pub loss_scale: f64,
    /// Truth: Coulomb friction on the link, N·m.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub coulomb_friction: f64,
    /// Truth: total backlash play, rad.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub backlash_width: f64,
    /// Truth: m·g·d of a link in a vertical plane, N·m.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub gravity_mgl: f64,
    /// Truth: link angle of the hanging rest position, rad.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub gravity_offset: f64,
    /// Truth: viscous link damping to ground, N·m·s/rad.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub link_damping: f64,
    /// Truth: lag of the PCL behind the housing thermocouple, s.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub thermal_lag: f64,
    /// Truth: Maxwell branch stiffness (frequency-dependent modulus), N·m/rad.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub maxwell_stiffness: f64,
    /// Truth: Maxwell relaxation time, s.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.1))]
    pub maxwell_time: f64,
    /// Heating during each run: the thermocouple rises by this much to the run temperature,
    /// T(t) = T − ΔT·exp(−3t/duration), K.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub heating_k: f64,
    /// Declared link inertia (metadata link_inertia_kgm2), kg·m².
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.018))]
    pub link_inertia: f64,
    /// Packaged FMU to use.
    #[cfg_attr(feature = "cli", arg(long))]
    pub fmu: Option<PathBuf>,
}

#[cfg(feature = "cli")]
#[derive(clap::Parser)]
struct SynthCli {
    #[cfg_attr(feature = "cli", command(flatten))]
    args: SynthArgs,
}

#[cfg(feature = "cli")]
impl SynthArgs {
    /// Options as `thermovia synth` would read them from `args` (without the program name).
    pub fn from_cli(args: &[&str]) -> Result<SynthArgs, clap::Error> {
        use clap::Parser;
        SynthCli::try_parse_from(std::iter::once("synth").chain(args.iter().copied())).map(|c| c.args)
    }
}

/// splitmix64: a small, well-mixed, seedable generator (Steele, Lea, Flood 2014).
pub struct SplitMix(u64);

impl SplitMix {
    pub fn new(seed: u64) -> Self {
        SplitMix(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        z ^ (z >> 31)
    }
    /// Uniform in (0, 1].
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    }
    /// Standard normal by Box–Muller.
    pub fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

pub fn quantize(x: f64) -> f64 {
    (x / ENCODER_QUANTUM).round() * ENCODER_QUANTUM
}

impl SynthArgs {
    pub fn truth_effects(&self) -> EffectValues {
        EffectValues {
            coulomb_friction: self.coulomb_friction,
            backlash_width: self.backlash_width,
            gravity_a: self.gravity_mgl * self.gravity_offset.cos(),
            gravity_b: self.gravity_mgl * self.gravity_offset.sin(),
            link_damping: self.link_damping,
            thermal_lag: self.thermal_lag,
            maxwell_stiffness: self.maxwell_stiffness,
            maxwell_time: self.maxwell_time,
            ..EffectValues::default()
        }
    }

    /// Standard deviation of everything added to a measured angle: Gaussian plus quantisation.
    pub fn noise_floor(&self) -> f64 {
        (self.noise_std.powi(2) + ENCODER_QUANTUM.powi(2) / 12.0).sqrt()
    }

    fn truth_json(&self) -> serde_json::Value {
        serde_json::json!({
            "storage_modulus_scale": self.storage_scale,
            "loss_modulus_scale": self.loss_scale,
            "coulomb_friction": {"torque_nm": self.coulomb_friction},
            "backlash": {"width_rad": self.backlash_width},
            "gravity": {"mgl_nm": self.gravity_mgl, "offset_rad": self.gravity_offset},
            "link_damping": {"damping_nms": self.link_damping},
            "thermal_lag": {"time_constant_s": self.thermal_lag},
            "frequency_dependent_modulus": {"stiffness_nm_per_rad": self.maxwell_stiffness, "relaxation_time_s": self.maxwell_time},
            "noise_std_rad": self.noise_std,
            "encoder_quantum_rad": ENCODER_QUANTUM,
            "noise_floor_rad": self.noise_floor(),
            "seed": self.seed,
        })
    }
}

/// File name of one synthetic run.
pub fn run_file_name(t: f64, f: f64) -> String {
    format!("run_{t}C_{f}Hz.csv")
}

/// Generates every run in memory: (file name, CSV text).
pub fn generate(args: &SynthArgs, fmu: Fmu) -> Result<Vec<(String, String)>, Box<dyn std::error::Error>> {
    let sim = Simulator::new(fmu, 1)?;
    if !(args.duration > 0.0) || !args.duration.is_finite() {
        return Err(format!("--duration {}: must be a finite number > 0 s", args.duration).into());
    }
    if !(args.rate > 0.0) || !args.rate.is_finite() {
        return Err(format!("--rate {}: must be a finite number > 0 Hz", args.rate).into());
    }
    crate::sweep::check_amplitude(args.amplitude_rad)?;
    let n = (args.duration * args.rate).round() as usize + 1;
    if n < 3 {
        return Err(format!(
            "--duration {} s at --rate {} Hz gives {n} samples: need at least 3",
            args.duration, args.rate
        )
        .into());
    }
    let model = RunModel {
        storage_scale: args.storage_scale,
        loss_scale: args.loss_scale,
        effects: args.truth_effects(),
        solver_tolerance: 1e-10,
        ..RunModel::default()
    };
    let mut rng = SplitMix::new(args.seed);
    let mut files = Vec::new();
    let mut inst = sim.fmu.instantiate(Some("synth"))?;
    for &temp in &args.temperatures {
        for &f in &args.frequencies {
            let time: Vec<f64> = (0..n).map(|k| k as f64 / args.rate).collect();
            let w = 2.0 * std::f64::consts::PI * f;
            let motor: Vec<f64> = time.iter().map(|t| args.amplitude_rad * (w * t).sin()).collect();
            let temp_c: Vec<f64> =
                time.iter().map(|t| temp - args.heating_k * (-3.0 * t / args.duration).exp()).collect();
            let input = SimInput {
                initial_link_speed: 0.0,
                housing_k: temp_c.iter().map(|t| t + crate::report::ZERO_CELSIUS).collect(),
                time: time.clone(),
                motor: motor.clone(),
                frequency_hz: f,
                link_inertia: Some(args.link_inertia),
                link0: 0.0,
                com_distance: 0.14,
                after_gap: false,
                housing_before: Default::default(),
                substeps: 1,
            };
            let link = simulate(&mut inst, &input, &model, None)?;
            let mut text = String::new();
            text += "# source=thermovia synth (truth model through the FMU; truth.json holds the truth)\n";
            text += &format!("# temperature_c={temp}\n# frequency_hz={f}\n# link_inertia_kgm2={}\n", args.link_inertia);
            text += &format!("# motor_amplitude_rad={}\n# sample_rate_hz={}\n", args.amplitude_rad, args.rate);
            text += "time_s,motor_angle_rad,link_angle_rad,temperature_c\n";
            for k in 0..n {
                let m = quantize(motor[k] + args.noise_std * rng.normal());
                let l = quantize(link[k] + args.noise_std * rng.normal());
                text += &format!("{:.4},{:.9},{:.9},{:.3}\n", time[k], m, l, temp_c[k]);
            }
            files.push((run_file_name(temp, f), text));
        }
    }
    files.push(("truth.json".into(), serde_json::to_string_pretty(&args.truth_json())? + "\n"));
    Ok(files)
}

/// Writes `files` (paths relative to `out`) as one folder, replacing an older `out` only when
/// all are written (`crate::output::replace_folder`).
pub fn write_atomically(out: &Path, files: &[(String, Vec<u8>)]) -> std::io::Result<()> {
    crate::output::replace_folder(out, |tmp| {
        for (f, bytes) in files {
            let p = tmp.join(f);
            if let Some(d) = p.parent() {
                std::fs::create_dir_all(d)?;
            }
            std::fs::File::create(&p)?.write_all(bytes)?;
        }
        Ok(())
    })
}

pub fn run(args: &SynthArgs) -> Result<(), Box<dyn std::error::Error>> {
    let fmu = crate::open_fmu(args.fmu.as_deref())?;
    let files = generate(args, fmu)?;
    let files: Vec<(String, Vec<u8>)> = files.into_iter().map(|(n, t)| (n, t.into_bytes())).collect();
    write_atomically(&args.out, &files)?;
    println!("wrote {} runs to {}", files.len() - 1, args.out.display());
    Ok(())
}
