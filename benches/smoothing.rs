//! `cargo bench --bench smoothing`: the equation error's smoothing (`signal::smooth_to_noise`, the
//! widest local quintic that takes out no more than the noise) on one run of 170 000 samples at
//! 5 kHz, a 0.95 Hz sine with 1e-4 rad of noise, its stamps even and jittered by up to ±15 % of the
//! period (a logger's; the quintic is then fitted in the samples' own times, window by window).
//! Prints each repetition and the median; SMOOTHING_BENCH_REPS repetitions (default 5).

use thermovia_tools::calibrate::signal::smooth_to_noise;

fn main() {
    let reps: usize = std::env::var("SMOOTHING_BENCH_REPS").ok().and_then(|v| v.parse().ok()).unwrap_or(5).max(1);
    for jitter in [0.0, 0.15] {
        let (t, x) = run(170_000, 2e-4, jitter);
        let mut seconds = Vec::with_capacity(reps);
        for rep in 0..reps {
            let start = std::time::Instant::now();
            let (half, smoothed, noise) = smooth_to_noise(&t, &x, t.len() / 100);
            let s = start.elapsed().as_secs_f64();
            println!(
                "jitter ±{:.0} %, rep {rep}: {:.1} ms, half window {half}, noise {noise:.3e} rad, mid value {:.9}",
                100.0 * jitter,
                1e3 * s,
                smoothed[t.len() / 2]
            );
            seconds.push(s);
        }
        seconds.sort_by(f64::total_cmp);
        println!(
            "smooth_to_noise, 170 000 samples, jitter ±{:.0} %: median {:.1} ms over {reps}",
            100.0 * jitter,
            1e3 * seconds[reps / 2]
        );
    }
}

/// Stamps k·period moved by up to ±`jitter` of a period (the ends kept), and the sine read at them.
fn run(n: usize, period: f64, jitter: f64) -> (Vec<f64>, Vec<f64>) {
    let mut state: u64 = 0x2545_F491_4F6C_DD1D;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let t: Vec<f64> = (0..n)
        .map(|k| k as f64 * period + if k > 0 && k + 1 < n { jitter * period * uniform() } else { 0.0 })
        .collect();
    let x = t.iter().map(|&u| 0.3 * (std::f64::consts::TAU * 0.95 * u).sin() + 1e-4 * uniform()).collect();
    (t, x)
}
