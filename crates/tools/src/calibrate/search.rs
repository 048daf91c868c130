//! The loop: fit the nominal model, diagnose, add the best-supported effect, refit everything,
//! keep it only if it earns its place, repeat until nothing in the library helps.

use super::diagnose::{rank, signatures, Candidate, Signatures};
use super::fit::{levenberg_marquardt, Effect, Fit, ModelSpec, Problem};

/// An effect is kept only when the refit lowers the BIC by more than this: "very strong" evidence
/// on the Kass & Raftery (1995) scale (ΔBIC > 10).
pub const BIC_MARGIN: f64 = 10.0;
/// Fraction of the residual's low-frequency structure (over white noise) an effect must remove.
pub const STRUCTURE_DROP: f64 = 1.0 / 3.0;
/// Refits tried per round, best-ranked first.
pub const TRIES_PER_ROUND: usize = 3;
pub const MAX_EFFECTS: usize = 4;
pub const MAX_ITERATIONS: usize = 25;
/// Levenberg–Marquardt iterations a shortlisted candidate gets before the comparison; the
/// winner then runs to convergence (speed: most of a search is spent on losers).
pub const SCREEN_ITERATIONS: usize = 4;

/// One round of diagnosis and what came of it.
#[derive(Clone, Debug)]
pub struct Round {
    pub signatures: Signatures,
    pub candidates: Vec<Candidate>,
    /// (effect, BIC before, BIC after, structure ratio before, after, kept)
    pub attempts: Vec<(Effect, f64, f64, f64, f64, bool)>,
}

pub struct Outcome {
    pub baseline: Fit,
    pub baseline_signatures: Signatures,
    pub final_fit: Fit,
    pub final_signatures: Signatures,
    pub rounds: Vec<Round>,
    /// Effects removed again by the backward check: (effect, BIC with it, BIC without).
    pub pruned: Vec<(Effect, f64, f64)>,
    pub unexplained: bool,
}

/// Starting points of the baseline, cheapest first: the closed-form transmission (frequency
/// response or equation error), the FMU's table, and the closed-form stiffness with the table's
/// damping (a closed form's damping is the least reliable number in it).
pub fn baseline_starts(prob: &Problem) -> Vec<(&'static str, Vec<f64>)> {
    let closed = prob.closed_form_start();
    let table = prob.table_start();
    let mut mixed = closed.clone();
    for g in 0..prob.n_groups {
        mixed[2 * g + 1] = table[2 * g + 1];
    }
    vec![("closed form", closed), ("material table", table), ("closed-form stiffness, table damping", mixed)]
}

/// The nominal model at its optimum (issue 10, item 3): every start is simulated once, and
/// Levenberg–Marquardt runs from the best one.
pub fn baseline(prob: &Problem) -> Result<(Fit, &'static str), String> {
    let spec = ModelSpec { effects: vec![] };
    let cost = |q: &[f64]| {
        prob.outputs(&spec, q).map(|o| prob.residual(&o).iter().map(|x| x * x).sum::<f64>()).unwrap_or(f64::INFINITY)
    };
    let (name, p0) = baseline_starts(prob)
        .into_iter()
        .map(|(n, p)| (cost(&p), n, p))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, n, p)| (n, p))
        .expect("three starts");
    Ok((levenberg_marquardt(prob, spec, p0, MAX_ITERATIONS)?, name))
}

pub fn calibrate(prob: &Problem) -> Result<Outcome, String> {
    search(prob, baseline(prob)?.0)
}

/// The search from a fitted baseline.
pub fn search(prob: &Problem, baseline: Fit) -> Result<Outcome, String> {
    let baseline_signatures = signatures(prob, &baseline);
    let mut current = baseline.clone();
    let mut sig = baseline_signatures.clone();
    let mut rounds = Vec::new();
    // until the residual is white at the noise floor, or nothing in the library earns its place
    // The baseline is always diagnosed (the ranking and its evidence are reported even for a
    // white residual); refits happen only while structure remains.
    while current.spec.effects.len() < MAX_EFFECTS && (rounds.is_empty() || !sig.white()) {
        let t = std::time::Instant::now();
        let candidates = rank(prob, &current, &sig);
        if std::env::var_os("THERMOVIA_DEBUG").is_some() {
            eprintln!("rank took {:?}", t.elapsed());
        }
        let mut round = Round { signatures: sig.clone(), candidates: candidates.clone(), attempts: vec![] };
        // The linearised ranking shortlists; the refits decide: of the shortlisted effects that
        // earn their place, the one with the lowest BIC is added.
        let mut accepted: Option<(Fit, Signatures)> = None;
        let shortlist = if sig.white() { 0 } else { TRIES_PER_ROUND };
        for c in candidates.iter().filter(|c| c.predicted_delta_bic < -BIC_MARGIN).take(shortlist) {
            let mut spec = current.spec.clone();
            spec.effects.push(c.effect);
            let mut p = current.p.clone();
            p.extend_from_slice(&c.start);
            // The transmission fitted without the effect may have absorbed it (friction mimicked
            // by a softer, more damped link): also try the closed-form transmission as the start
            // and keep the better one.
            let mut p_table = p.clone();
            p_table[..2 * prob.n_groups].copy_from_slice(&prob.closed_form_start());
            let cost = |q: &[f64]| {
                prob.outputs(&spec, q)
                    .map(|o| prob.residual(&o).iter().map(|x| x * x).sum::<f64>())
                    .unwrap_or(f64::INFINITY)
            };
            if cost(&p_table) < cost(&p) {
                p = p_table;
            }
            let t = std::time::Instant::now();
            let Ok(refit) = levenberg_marquardt(prob, spec, p, SCREEN_ITERATIONS) else { continue };
            if std::env::var_os("THERMOVIA_DEBUG").is_some() {
                eprintln!("refit {} took {:?}, {} iterations", c.effect.name(), t.elapsed(), refit.iterations);
            }
            let refit_sig = signatures(prob, &refit);
            // it earns its place if BIC says so and the residual lost the structure it explained:
            // at least STRUCTURE_DROP of the low-frequency excess over white noise (BIC alone,
            // with N = every sample, over-rewards small effects fitting correlated leftovers)
            let excess = |x: f64| (x - 1.0).max(0.0);
            let keep = refit.bic() < current.bic() - BIC_MARGIN
                && excess(refit_sig.structure_ratio) <= (1.0 - STRUCTURE_DROP) * excess(sig.structure_ratio);
            round.attempts.push((
                c.effect,
                current.bic(),
                refit.bic(),
                sig.structure_ratio,
                refit_sig.structure_ratio,
                keep,
            ));
            if keep && accepted.as_ref().is_none_or(|a| refit.bic() < a.0.bic()) {
                accepted = Some((refit, refit_sig));
            }
        }
        if let Some((f, _)) = &accepted {
            for a in round.attempts.iter_mut() {
                a.5 = a.5 && f.spec.effects.last() == Some(&a.0);
            }
        }
        // the winner runs to convergence
        if let Some((f, _)) = &accepted {
            if f.iterations >= SCREEN_ITERATIONS {
                if let Ok(done) = levenberg_marquardt(prob, f.spec.clone(), f.p.clone(), MAX_ITERATIONS) {
                    if done.sse <= f.sse {
                        let s = signatures(prob, &done);
                        accepted = Some((done, s));
                    }
                }
            }
        }
        rounds.push(round);
        match accepted {
            Some((f, s)) => {
                current = f;
                sig = s;
            }
            None => break,
        }
    }
    // Backward check: an effect added early may be redundant once a later one is in (a Maxwell
    // branch standing in for link damping). Drop any whose removal does not cost BIC_MARGIN.
    let mut pruned = Vec::new();
    let mut changed = current.spec.effects.len() > 1;
    while changed {
        changed = false;
        for &e in current.spec.effects.clone().iter() {
            let spec = ModelSpec { effects: current.spec.effects.iter().copied().filter(|&x| x != e).collect() };
            let mut p = current.p[..2 * prob.n_groups].to_vec();
            for (o, x) in current.spec.offsets(prob.n_groups) {
                if x != e {
                    p.extend_from_slice(&current.p[o..o + x.params().len()]);
                }
            }
            let Ok(refit) = levenberg_marquardt(prob, spec, p, MAX_ITERATIONS) else { continue };
            if refit.bic() < current.bic() + BIC_MARGIN {
                pruned.push((e, current.bic(), refit.bic()));
                sig = signatures(prob, &refit);
                current = refit;
                changed = current.spec.effects.len() > 1;
                break;
            }
        }
    }
    let unexplained = !sig.white();
    Ok(Outcome {
        baseline,
        baseline_signatures,
        final_fit: current,
        final_signatures: sig,
        rounds,
        pruned,
        unexplained,
    })
}
