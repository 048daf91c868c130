//! The loop: fit the nominal model, diagnose, add the best-supported effect, refit everything,
//! keep it only if it earns its place, repeat until nothing in the library helps.

use super::diagnose::{rank, signatures, Signatures};
use super::fit::{
    levenberg_marquardt, regressor_columns, DampingLaw, Effect, EquationError, Fit, ModelSpec, NormalEquations,
    Problem, SpringBank, EQUATION_ERROR_EFFECTS,
};

use super::stepwise::{debug, Attempt, Ranked, Record, Rig, Verdict};
pub use super::stepwise::{
    Budget, BIC_MARGIN, COMBINATION_PASSES, MAX_EFFECTS, PAIR_POOL, SHORTLIST_SHARE, TRIES_PER_ROUND,
};
use nalgebra::{DMatrix, DVector};

/// Fraction of the residual's low-frequency structure (over white noise) an effect must remove.
pub const STRUCTURE_DROP: f64 = 1.0 / 3.0;
/// How far above its noise floor (the link sensor's, `Signatures::noise_floor`) a model's rms must
/// be for a refit that lowered the BIC and some of the structure to be ranked in its turn where
/// nothing earned its place (`Rig::partly_earned`): the factor the unexplained rule uses against
/// that floor without the motor log's simulated error, where a right model has stood 1.52× above.
pub const FAR_ABOVE_FLOOR: f64 = super::FAR_ABOVE_COUNT_FLOOR;
pub const MAX_ITERATIONS: usize = 25;
/// Levenberg–Marquardt iterations a shortlisted candidate gets before the comparison; the
/// winner then runs to convergence (speed: most of a search is spent on losers).
pub const SCREEN_ITERATIONS: usize = 4;

/// The equation error's best subsets refitted through the FMU when combinations are tried.
pub const SUBSETS_REFITTED: usize = 3;

/// An effect earns its place if BIC falls by more than `BIC_MARGIN` and the residual loses at least
/// `STRUCTURE_DROP` of its low-frequency excess over white noise (BIC alone, with N = every
/// sample, over-rewards small effects fitting correlated leftovers).
fn earns_its_place(current: &Fit, sig: &Signatures, refit: &Fit, refit_sig: &Signatures) -> bool {
    let excess = |x: f64| (x - 1.0).max(0.0);
    refit.bic() < current.bic() - BIC_MARGIN
        && excess(refit_sig.structure_ratio) <= (1.0 - STRUCTURE_DROP) * excess(sig.structure_ratio)
}

/// Whether a model's residual is more than [`FAR_ABOVE_FLOOR`] times its noise floor: several
/// effects may be missing there, each removing only its part of the structure.
fn far_above_floor(sig: &Signatures) -> bool {
    sig.rmse > FAR_ABOVE_FLOOR * sig.noise_floor
}

/// A screening refit (at most `SCREEN_ITERATIONS`) with its signatures, run on to convergence when
/// the cap cut it off while its BIC already beat `current`'s by the margin but its structure did not
/// yet earn its place: the cap is for speed, not a verdict. Campaign rig 36's Stribeck excess (1.8×
/// its Coulomb level) was rejected after 4 iterations at a BIC 105 000 below the current model's;
/// converged in 12, every parameter within 1 % and 1.02× the floor.
fn unless_cut_off(prob: &Problem, current: &Fit, current_sig: &Signatures, screened: Fit) -> (Fit, Signatures) {
    let sig = signatures(prob, &screened);
    let promising = screened.iterations >= SCREEN_ITERATIONS
        && screened.bic() < current.bic() - BIC_MARGIN
        && !earns_its_place(current, current_sig, &screened, &sig);
    if promising {
        if let Ok(f) = levenberg_marquardt(prob, screened.spec.clone(), screened.p.clone(), MAX_ITERATIONS) {
            let s = signatures(prob, &f);
            return (f, s);
        }
    }
    (screened, sig)
}

/// What a device refit's verdict rests on besides BIC: the residual's low-frequency structure over
/// white noise before and after, and (for a combination) the temperature groups whose stiffness
/// it took to a bound (`combination_verdict`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Evidence {
    pub structure: (f64, f64),
    pub newly_near_bound: Option<usize>,
}

/// `refit` against `current` (same data): BIC and the structure ratios.
fn verdict(current: &Fit, sig: &Signatures, refit: &Fit, refit_sig: &Signatures) -> Verdict<Evidence> {
    Verdict {
        keep: earns_its_place(current, sig, refit, refit_sig),
        bic_before: current.bic(),
        bic_after: refit.bic(),
        detail: Evidence { structure: (sig.structure_ratio, refit_sig.structure_ratio), newly_near_bound: None },
    }
}

/// Share of every run the candidates are screened on (its start), when that still holds three
/// cycles of every sinusoidal run and 3 s of any other: the screening refits then cost this share.
pub const SCREEN_SHARE: f64 = 0.35;

/// Whether `SCREEN_SHARE` of every run holds three cycles of a sinusoidal run, 3 s of any other.
fn screening_share_fits(prob: &Problem) -> bool {
    prob.inputs.iter().zip(prob.sinusoidal()).all(|(i, &sinusoidal)| {
        let span = SCREEN_SHARE * (i.time[i.time.len() - 1] - i.time[0]);
        let need = if sinusoidal { 3.0 / i.frequency_hz } else { 3.0 };
        span >= need
    })
}

/// The first `SCREEN_SHARE` of every run, with the current fit evaluated on it; None when the
/// runs are too short for that (the full runs are screened).
fn screening_problem<'a>(prob: &Problem<'a>, fit: &Fit) -> Option<(Problem<'a>, Fit, Signatures)> {
    if !screening_share_fits(prob) {
        return None;
    }
    let sprob = prob.truncated(SCREEN_SHARE);
    let f = Fit::evaluate_with_jacobian(&sprob, fit.spec.clone(), fit.p.clone())?;
    let s = signatures(&sprob, &f);
    Some((sprob, f, s))
}

/// Whether group g's transmission in `p` is no start for a refit: on a bound, or dragging the
/// link through its damper (`Problem::transmission_dragging`).
fn no_start(prob: &Problem, g: usize, p: &[f64]) -> bool {
    prob.transmission_at_bound(g, p) || prob.transmission_dragging(g, p)
}

/// A combination's verdict against `current`: [`verdict`]'s, and kept only where `refit` puts no
/// temperature group's stiffness at or near a bound that `current` had it away from
/// (`Problem::stiffness_near_bound`); those groups are counted in the detail.
fn combination_verdict(
    prob: &Problem,
    current: &Fit,
    sig: &Signatures,
    refit: &Fit,
    refit_sig: &Signatures,
) -> Verdict<Evidence> {
    let newly = (0..prob.n_groups)
        .filter(|&g| {
            let side = prob.stiffness_near_bound(g, &refit.p);
            side != 0 && side != prob.stiffness_near_bound(g, &current.p)
        })
        .count();
    let mut v = verdict(current, sig, refit, refit_sig);
    v.detail.newly_near_bound = Some(newly);
    v.keep &= newly == 0;
    v
}

/// The share of the time left that a combination's fits may take. A combination refits several
/// proposals, each from several starts; on a long, fast-sampled run with play and friction these
/// took the whole budget (fresh rig 761: 5 kHz, 222 000 samples, 109 s of its 120 s on proposals
/// with a play it does not have) and no round ran; given half, the rounds found its friction and
/// damping (5.3× its floor → 1.07×).
const COMBINATION_SHARE: f64 = 0.5;

/// A round of the device's search: the screened residual's signatures, the ranking, the refits
/// with their [`Evidence`].
pub type Round = super::stepwise::Round<Effect, Signatures, Evidence>;
/// An effect set refitted at once, with its [`Evidence`].
pub type CombinationAttempt = Attempt<Effect, Evidence>;

pub struct Outcome {
    /// Rounds, combinations, the backward check and the budget (`stepwise::search`).
    pub record: Record<Effect, Signatures, Evidence>,
    pub baseline: Fit,
    pub baseline_signatures: Signatures,
    pub final_fit: Fit,
    pub final_signatures: Signatures,
    /// The model after each step the search accepted (the baseline first, the final model last).
    pub path: Vec<(Fit, Signatures)>,
    pub unexplained: bool,
    /// Damping laws compared (baseline and after each added effect).
    pub laws: Vec<LawRow>,
    pub law_reason: String,
    /// Backlash's contact laws compared, when the final model has backlash.
    pub backlash_laws: Option<BacklashLawChoice>,
}

/// Backlash's contact law chosen by evidence: both laws fitted from the search's parameters.
#[derive(Clone, Debug)]
pub struct BacklashLawChoice {
    /// (law, rmse, bic): the clipped law, then ElastoBacklash (absent when its fit failed).
    pub compared: Vec<(&'static str, f64, f64)>,
    pub elasto: bool,
    /// The width before and after the final scan ([`scan_backlash_width`]), rad; None where the scan
    /// kept it.
    pub width_scan: Option<(f64, f64)>,
}

/// Factors the backlash width is scanned by around the fit's own, each with the rest held.
pub const WIDTH_SCAN: [f64; 4] = [0.8, 0.9, 1.1, 1.25];
/// Rounds of the scan at most (each a simulation per factor and a refit).
const WIDTH_SCAN_ROUNDS: usize = 4;

/// The backlash width scanned in steps of a tenth or more of itself, the rest held, and the model
/// refitted from the best width that lowers the BIC by more than [`BIC_MARGIN`], while one does:
/// the contact's timing makes the cost rugged at the scale of a Jacobian's difference step (1e-3 of
/// the width), so Levenberg–Marquardt can stop on that ripple while the cost still falls steadily
/// over larger steps (campaign rig 169: 0.803 mrad against the truth's 0.894, the error falling
/// from 1.79e-4 rad at 0.803 to 1.35e-4 at 0.88–0.93 with K and C held). Only the final model is
/// scanned: a larger difference step in every refit took other searches down other paths.
/// Returns the model with the width before and after, where the scan moved it.
pub fn scan_backlash_width(prob: &Problem, mut current: Fit, budget: &Budget) -> (Fit, Option<(f64, f64)>) {
    let Some(w) = current.spec.offset_of(Effect::Backlash, prob.n_groups) else {
        return (current, None);
    };
    let from = current.p[w];
    let n = current.n as f64;
    for _ in 0..WIDTH_SCAN_ROUNDS {
        if current.p[w] <= 0.0 || !budget.affords(2.0) {
            break;
        }
        let best = WIDTH_SCAN
            .iter()
            .map(|f| {
                let mut p = current.p.clone();
                p[w] *= f;
                (prob.cost(&current.spec, &p), p)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0));
        // the same parameters: the BIC moves by n ln(SSE ratio)
        let Some((sse, p)) = best.filter(|(sse, _)| n * (sse / current.sse).ln() < -BIC_MARGIN) else { break };
        debug(format_args!(
            "backlash width {:.4e} → {:.4e}: SSE {:.4e} → {:.4e}",
            current.p[w], p[w], current.sse, sse
        ));
        match budget.timed(|| levenberg_marquardt(prob, current.spec.clone(), p, MAX_ITERATIONS)) {
            Ok(f) if f.bic() < current.bic() - BIC_MARGIN => current = f,
            _ => break,
        }
    }
    let moved = (current.p[w] != from).then_some((from, current.p[w]));
    (current, moved)
}

/// With backlash in the model, the clipped law (the search's) and Modelica's ElastoBacklash
/// (docs/physics.md §10) fitted from the same parameters; ElastoBacklash is kept when it lowers the
/// BIC by more than [`BIC_MARGIN`] (the same number of parameters, so by the SSE alone). The fitting
/// runs choose; held-out runs never do.
pub fn choose_backlash_law(
    prob: &Problem,
    current: Fit,
    sig: Signatures,
) -> (Fit, Signatures, Option<BacklashLawChoice>) {
    if !current.spec.effects.contains(&Effect::Backlash) {
        return (current, sig, None);
    }
    let spec = ModelSpec { elasto_backlash: true, ..current.spec.clone() };
    let elasto = levenberg_marquardt(prob, spec, current.p.clone(), MAX_ITERATIONS).ok();
    let mut compared = vec![("clipped", current.rmse(), current.bic())];
    if let Some(e) = &elasto {
        compared.push(("elasto_backlash", e.rmse(), e.bic()));
    }
    match elasto {
        Some(e) if e.bic() < current.bic() - BIC_MARGIN => {
            let sig = signatures(prob, &e);
            (e, sig, Some(BacklashLawChoice { compared, elasto: true, width_scan: None }))
        }
        _ => (current, sig, Some(BacklashLawChoice { compared, elasto: false, width_scan: None })),
    }
}

/// Starting points of the baseline, cheapest first: the closed-form transmission (frequency
/// response or equation error), the FMU's table, and the closed-form stiffness with the table's
/// damping (a closed form's damping is the least reliable number in it).
pub fn baseline_starts(prob: &Problem, law: DampingLaw) -> Vec<(&'static str, Vec<f64>)> {
    let closed = prob.closed_form_start(law);
    let table = prob.table_start();
    let mut mixed = closed.clone();
    for g in 0..prob.n_groups {
        mixed[2 * g + 1] = table[2 * g + 1];
    }
    let mut starts =
        vec![("closed form", closed), ("material table", table), ("closed-form stiffness, table damping", mixed)];
    if let Some(e) = prob.equation_error_start(law, None) {
        starts.push(("equation error", e));
    }
    starts
}

/// Levenberg–Marquardt from the cheapest of several starts (each simulated once).
fn fit_from_best(prob: &Problem, spec: ModelSpec, starts: Vec<Vec<f64>>, max_iter: usize) -> Result<Fit, String> {
    let p0 = best_start(prob, &spec, starts).ok_or("no start")?;
    levenberg_marquardt(prob, spec, p0, max_iter)
}

/// The start of lowest cost (each simulated once); None without a start.
fn best_start(prob: &Problem, spec: &ModelSpec, starts: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    starts.into_iter().map(|p| (prob.cost(spec, &p), p)).min_by(|a, b| a.0.total_cmp(&b.0)).map(|(_, p)| p)
}

/// Levenberg–Marquardt from every start, the lowest BIC kept: where the starts' costs say nothing
/// of the valley each leads to (`candidate_starts`' Stribeck velocities).
fn fit_from_each(prob: &Problem, spec: &ModelSpec, starts: Vec<Vec<f64>>, max_iter: usize) -> Result<Fit, String> {
    let mut fits = starts.into_iter().map(|p| levenberg_marquardt(prob, spec.clone(), p, max_iter));
    let first = fits.next().ok_or("no start")?;
    fits.fold(first, |best, f| match (best, f) {
        (Ok(b), Ok(f)) => Ok(if f.bic() < b.bic() { f } else { b }),
        (Err(_), f) => f,
        (b, Err(_)) => b,
    })
}

/// The nominal model at its optimum under one damping law (issue 10, item 3): every start is
/// simulated once, and Levenberg–Marquardt runs from the best one, held to `end` like every later
/// fit (it stops there at its best so far; None: no end of its own). Only where `end` comes before
/// its first Jacobian is the best start taken as it is (with its Jacobian), under the simulator's
/// own deadline (`hard_deadline`'s backstop), so that there is a model to report. Fresh rig 939
/// (2.3 million samples) had its baseline run 25 iterations to 90 s of a 120 s budget alone, and to
/// the backstop, 154 s, beside another rig.
pub fn baseline(prob: &Problem, (law, springs): Structure, end: Option<std::time::Instant>) -> Result<Fit, String> {
    let spec = ModelSpec { effects: vec![], law, springs, elasto_backlash: false };
    let starts = baseline_starts(prob, law).into_iter().map(|s| s.1).collect();
    let p0 = best_start(prob, &spec, starts).ok_or("no start")?;
    let fitted = prob.sim.within(end, || levenberg_marquardt(prob, spec.clone(), p0.clone(), MAX_ITERATIONS));
    match fitted {
        Err(_) if end.is_some_and(|end| std::time::Instant::now() >= end) => levenberg_marquardt(prob, spec, p0, 0),
        fitted => fitted,
    }
}

/// The combinations of linear effects ([`EQUATION_ERROR_EFFECTS`]) the equation error supports,
/// with the transmission of every temperature group fitted beside them (so neither absorbs the
/// other, and no bound pins it): of every subset (asymmetric friction only with Coulomb
/// friction), the lowest BIC on the regression's independent rows among those in which each
/// effect's removal costs more than `BIC_MARGIN`: the best `count` of them, best first. The
/// regression is formed once, on the rows where the link moves (at rest, friction holds any torque
/// up to its level, and no row there tells friction from play); every subset is solved from its
/// normal equations.
pub fn equation_error_subsets(prob: &Problem, law: DampingLaw, count: usize) -> Vec<Vec<Effect>> {
    let all = EQUATION_ERROR_EFFECTS;
    // with backlash: the same regression at each width of the grid (the best width per subset)
    let widths: Vec<f64> = std::iter::once(0.0).chain(prob.backlash_width_grid()).collect();
    let Some(mut with_play) = prob.normal_equations_at(law, &all, &widths, true) else { return Vec::new() };
    let normal: NormalEquations = with_play.remove(0);
    let n_t = 2 * prob.n_groups;
    let mut offsets = Vec::with_capacity(all.len());
    let mut next = n_t;
    for e in all {
        offsets.push(next);
        next += regressor_columns(e);
    }
    let bit = |e: Effect| 1u32 << all.iter().position(|&x| x == e).expect("in the list");
    // asymmetric friction only over Coulomb friction, and no effect beside the one it takes the
    // place of (`Effect::takes_place_of`)
    let beside = |mask: u32, e: Effect| mask & bit(e) != 0 && e.takes_place_of().is_some_and(|d| mask & bit(d) != 0);
    let valid = |mask: u32| {
        (mask & bit(Effect::AsymmetricFriction) == 0 || mask & bit(Effect::CoulombFriction) != 0)
            && !all.iter().any(|&e| beside(mask, e))
    };
    let bic: Vec<Option<f64>> = (0..1u32 << all.len())
        .map(|mask| {
            if !valid(mask) {
                return None;
            }
            let columns: Vec<usize> = (0..n_t)
                .chain(
                    (0..all.len())
                        .filter(|i| mask >> i & 1 == 1)
                        .flat_map(|i| offsets[i]..offsets[i] + regressor_columns(all[i])),
                )
                .collect();
            if mask & bit(Effect::Backlash) == 0 {
                let (_, sse) = normal.solve(&columns)?;
                Some(normal.bic(sse, columns.len()))
            } else {
                let sse = with_play.iter().filter_map(|n| n.solve(&columns)).map(|(_, sse)| sse).reduce(f64::min)?;
                Some(normal.bic(sse, columns.len() + 1))
            }
        })
        .collect();
    let needed = |mask: u32| {
        (0..all.len()).filter(|i| mask >> i & 1 == 1).all(|i| {
            match (bic[(mask & !(1 << i)) as usize], bic[mask as usize]) {
                (Some(without), Some(with)) => without > with + BIC_MARGIN,
                // removing Coulomb friction from under its asymmetry: judged with both removed
                _ => bic[(mask & !(1 << i) & !bit(Effect::AsymmetricFriction)) as usize]
                    .zip(bic[mask as usize])
                    .is_none_or(|(without, with)| without > with + BIC_MARGIN),
            }
        })
    };
    let mut ranked: Vec<u32> = (0..1u32 << all.len()).filter(|&m| bic[m as usize].is_some() && needed(m)).collect();
    ranked.sort_by(|&a, &b| {
        bic[a as usize].unwrap_or(f64::INFINITY).total_cmp(&bic[b as usize].unwrap_or(f64::INFINITY))
    });
    let effects_of = |m: u32| -> Vec<Effect> { (0..all.len()).filter(|i| m >> i & 1 == 1).map(|i| all[i]).collect() };
    debug(format_args!(
        "equation error subsets (BIC on {:.0} independent rows): {:?}; none {:.1}",
        normal.independent,
        ranked.iter().take(count).map(|&m| (effects_of(m), bic[m as usize].unwrap_or(f64::NAN))).collect::<Vec<_>>(),
        bic[0].unwrap_or(f64::NAN),
    ));
    ranked.into_iter().take(count).map(effects_of).collect()
}

/// How far effect `e` shows in `fit`'s outputs, from its linearised share J_e·p_e (its levels only:
/// a log-parameter only shapes one, a Stribeck speed, a Maxwell time): rms over every sample
/// against the noise floor, and at its own time scale (`fit::own_time_scale_share`, the drive's
/// rule) against the residual, the larger; above 1 it shows. At its time scale only the part of
/// the share the other parameters cannot take over counts (`fit::share_beyond_the_rest`): averaged
/// over a stroke, a gravity of a thousandth of its load's size still reads above a residual whose
/// slow part the fit has nulled (fresh rig 303). Per sample alone where the residual is not the
/// runs' samples in order. None where the fit has no Jacobian to tell. Fresh rig 304's friction
/// asymmetry under a 1 000-count encoder moves the link by less than a count, but for every
/// stroke: kept at a BIC 1 100 lower, it was dropped as unseen while the rule was per sample alone.
fn visibility(prob: &Problem, fit: &Fit, floor: f64, e: Effect) -> Option<f64> {
    let cols = level_columns(fit, prob.n_groups, e);
    let (rows, columns) = fit.jacobian.shape();
    if cols.is_empty() || rows == 0 || columns != fit.p.len() {
        return None;
    }
    let linearised = || super::fit::linearised_shares(&fit.jacobian, &fit.p, &cols);
    let share =
        if e.level_is_linear() { linearised() } else { simulated_share(prob, fit, &cols).unwrap_or_else(linearised) };
    let per_sample = super::fit::rms(&share) / floor;
    let lengths = prob.lengths();
    if rows != fit.residual.len() || lengths.iter().sum::<usize>() != rows {
        return Some(per_sample);
    }
    let own: Vec<usize> =
        fit.spec.offset_of(e, prob.n_groups).map_or_else(Vec::new, |o| (o..o + e.params().len()).collect());
    let beyond = super::fit::share_beyond_the_rest(&fit.jacobian, &share, &own);
    let time_scale = super::fit::own_time_scale_share(&beyond, &fit.residual, &lengths, fit.p.len());
    debug(format_args!(
        "visibility of {e:?}: per sample {per_sample:.3}, beyond the rest {:.3}, own time scale {time_scale:.3}, rmse {:.3} of the floor, n {rows}",
        super::fit::rms(&beyond) / floor,
        fit.rmse() / floor
    ));
    Some(per_sample.max(time_scale))
}

/// What the levels `cols` of `fit` do to its outputs, simulated: the fit's outputs less the same
/// model's with those levels at zero (for an effect whose outputs do not move in proportion to
/// its levels, `Effect::level_is_linear`). None where the model without them does not simulate or
/// the fit's outputs are not the problem's samples.
fn simulated_share(prob: &Problem, fit: &Fit, cols: &[usize]) -> Option<Vec<f64>> {
    let mut without = fit.p.clone();
    for &c in cols {
        without[c] = 0.0;
    }
    let outputs = prob.outputs(&fit.spec, &without)?;
    let share: Vec<f64> =
        fit.outputs.iter().zip(&outputs).flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| x - y)).collect();
    (share.len() == fit.residual.len() && fit.outputs.iter().map(Vec::len).eq(outputs.iter().map(Vec::len)))
        .then_some(share)
}

/// The indices of `e`'s levels in `fit`'s parameters: the effect is gone when they are zero. A
/// Stribeck speed or a Maxwell time (fitted as logarithms) only shapes a level: at zero it would
/// be a speed or a time of 1 in the file's unit, not the effect's absence.
fn level_columns(fit: &Fit, n_groups: usize, e: Effect) -> Vec<usize> {
    fit.spec
        .offsets(n_groups)
        .into_iter()
        .filter(|&(_, x)| x == e)
        .flat_map(|(o, x)| {
            x.params().iter().enumerate().filter(|(_, q)| !q.0.starts_with("ln_")).map(move |(k, _)| o + k)
        })
        .collect()
}

/// The linearised BIC cost of `e`'s removal from `fit`: its levels forced to zero while the rest
/// re-adjusts, and every parameter of it gone (`stepwise::removal_delta_bic`).
fn removal_cost(fit: &Fit, n_groups: usize, e: Effect) -> f64 {
    super::stepwise::removal_delta_bic(
        &fit.jacobian,
        &fit.p,
        fit.sse,
        &level_columns(fit, n_groups, e),
        e.params().len(),
    )
}

/// The issue's line of "explained": a final rms error at most this many times the noise floor.
pub const EXPLAINED_LINE: f64 = 1.2;

/// Whether a model at rms `with_rmse` whose refit without an effect stands at `without_rmse` lost
/// more than the noise (rms `floor`) can hide: a systematic share s adds to the noise's rms as
/// √(floor² + s²), and a right model without it is still explained (within `EXPLAINED_LINE`) while
/// s ≤ floor·√(line² − 1), 0.66 of the floor. The rise in mean square measures s wherever the
/// model stands, as long as the share is independent of what the model leaves.
pub fn absence_shows(with_rmse: f64, without_rmse: f64, floor: f64) -> bool {
    without_rmse.powi(2) - with_rmse.powi(2) > (EXPLAINED_LINE.powi(2) - 1.0) * floor.powi(2)
}

/// The effects of `fit` no sample can show (`visibility` at most 1).
fn below_noise(prob: &Problem, fit: &Fit, floor: f64) -> Vec<Effect> {
    fit.spec.effects.iter().copied().filter(|&e| visibility(prob, fit, floor, e).is_some_and(|v| v <= 1.0)).collect()
}

/// How far `fit`'s gravity moves the link beyond what a constant load would: its torque
/// −A sin(θ − θ0) less that torque's mean over every measured link angle, rms, through the softest
/// fitted stiffness (a quasi-static deflection, the convention of the report's equivalent forms,
/// `report::gravity_offset_form`). None without a gravity.
fn gravity_beyond_a_load(prob: &Problem, fit: &Fit) -> Option<f64> {
    let o = fit.spec.offset_of(Effect::Gravity, prob.n_groups)?;
    // (a, b) = A (cos θ0, sin θ0): −A sin(θ − θ0) = −a sin θ + b cos θ
    let (a, b) = (fit.p[o], fit.p[o + 1]);
    let torque = || prob.measured.iter().flatten().map(|t| -a * t.sin() + b * t.cos());
    let n = prob.measured.iter().map(Vec::len).sum::<usize>();
    if n == 0 {
        return None;
    }
    let mean = torque().sum::<f64>() / n as f64;
    let spread = (torque().map(|t| (t - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    Some(spread / prob.softest_stiffness(&fit.p))
}

/// `fit`'s model and parameters without the effects `drop` (the backlash law re-chosen later).
fn spec_without(fit: &Fit, n_groups: usize, drop: &[Effect]) -> (ModelSpec, Vec<f64>) {
    let spec = ModelSpec {
        effects: fit.spec.effects.iter().copied().filter(|x| !drop.contains(x)).collect(),
        law: fit.spec.law,
        springs: fit.spec.springs,
        elasto_backlash: false,
    };
    let mut p = fit.p[..2 * n_groups].to_vec();
    for (o, x) in fit.spec.offsets(n_groups) {
        if !drop.contains(&x) {
            p.extend_from_slice(&fit.p[o..o + x.params().len()]);
        }
    }
    (spec, p)
}

/// The equation error's combinations refitted at once through the FMU: their linear effects with
/// the current fit's other effects (backlash, thermal lag, ...) at their values, from the equation
/// error's transmission, the current one and the closed form, under every allowed structure.
/// Screened, then the best run to convergence; kept only if it earns its place against `current`
/// on the screening share and on every sample. None when the equation error proposes nothing new
/// (`refitted` remembers what earlier passes refitted).
fn try_combination(
    prob: &Problem,
    screen: &Option<(Problem, Fit, Signatures)>,
    current: &Fit,
    sig: &Signatures,
    stage: &'static str,
    structures: &[Structure],
    refitted: &mut Vec<(Structure, Vec<Effect>)>,
) -> Option<(CombinationAttempt, Option<(Fit, Signatures)>)> {
    let n_t = 2 * prob.n_groups;
    let kept_effects: Vec<Effect> =
        current.spec.effects.iter().copied().filter(|e| !EQUATION_ERROR_EFFECTS.contains(e)).collect();
    let mut others = Vec::new();
    for (o, e) in current.spec.offsets(prob.n_groups) {
        if !EQUATION_ERROR_EFFECTS.contains(&e) {
            others.extend_from_slice(&current.p[o..o + e.params().len()]);
        }
    }
    // under the current structure and every other the data allow (which damping law is right
    // shows only once the effects are in)
    let first = (current.spec.law, current.spec.springs);
    let laws: Vec<Structure> =
        std::iter::once(first).chain(structures.iter().copied().filter(|&s| s != first)).collect();
    // The equation error ranks close structures unreliably (link damping under the wrong damping
    // law, asymmetric friction against a constant load): the best few subsets of every law are
    // proposed under every law.
    let mut subsets: Vec<Vec<Effect>> = Vec::new();
    for &(law, _) in &laws {
        for subset in equation_error_subsets(prob, law, SUBSETS_REFITTED) {
            let same = subset.len() + kept_effects.len() == current.spec.effects.len()
                && subset.iter().all(|e| current.spec.effects.contains(e));
            if !subset.is_empty() && !same && !subsets.contains(&subset) {
                subsets.push(subset);
            }
        }
    }
    let mut proposals: Vec<(Structure, Vec<Effect>, EquationError)> = Vec::new();
    for &structure in &laws {
        for subset in &subsets {
            let mut effects = kept_effects.clone();
            effects.extend_from_slice(subset);
            // an excess goes only with its base (`Effect::defined_over`); a model an earlier pass
            // refitted from the same equation error is not refitted again (only the current
            // transmission's start would differ)
            let excess_alone = effects.iter().any(|e| e.defined_over().is_some_and(|b| !effects.contains(&b)));
            let key = (structure, effects);
            if excess_alone || refitted.contains(&key) {
                continue;
            }
            refitted.push(key);
            if let Some(ee) = prob.equation_error(structure.0, subset) {
                proposals.push((structure, subset.clone(), ee));
            }
        }
    }
    if proposals.is_empty() {
        return None;
    }
    // (the current transmission only when no group is at a bound or dragging: a rigid or limp link
    // is no start, and a stiff one with friction is slow to simulate)
    let feasible = !(0..prob.n_groups).any(|g| no_start(prob, g, &current.p));
    let (sprob, scurrent, ssig) = screened(screen, prob, current, sig);
    let t = std::time::Instant::now();
    // Each structure's best subset from every start (a transmission that absorbed an effect, or
    // sits at a bound, is a valley of its own), the others from their cheapest start.
    let mut fits: Vec<Fit> = Vec::new();
    let mut first_of: Vec<Structure> = Vec::new();
    for ((law, springs), subset, ee) in &proposals {
        let mut effects = kept_effects.clone();
        effects.extend_from_slice(subset);
        let spec = ModelSpec { effects, law: *law, springs: *springs, elasto_backlash: false };
        let closed = prob.closed_form_start(*law);
        let starts: Vec<Vec<f64>> = [Some(&ee.p[..n_t]), feasible.then_some(&current.p[..n_t]), Some(&closed[..n_t])]
            .into_iter()
            .flatten()
            .map(|transmission| {
                let mut q = transmission.to_vec();
                q.extend_from_slice(&others);
                q.extend_from_slice(&ee.p[n_t..]);
                q
            })
            .collect();
        if !first_of.contains(&(*law, *springs)) {
            first_of.push((*law, *springs));
            fits.extend(
                starts.into_iter().filter_map(|q| levenberg_marquardt(sprob, spec.clone(), q, SCREEN_ITERATIONS).ok()),
            );
        } else if let Ok(f) = fit_from_best(sprob, spec, starts, SCREEN_ITERATIONS) {
            fits.push(f);
        }
    }
    debug(format_args!(
        "combination fits: {:?} against current {:.1}",
        fits.iter().map(|f| (f.spec.effects.clone(), f.spec.law, f.bic().round())).collect::<Vec<_>>(),
        scurrent.bic()
    ));
    let mut screened = fits.iter().min_by(|a, b| a.bic().total_cmp(&b.bic()))?.clone();
    // the groups' transmissions are nearly separable: each group takes the fit that suits its own
    // runs best (one group pinned at a bound need not sink the others)
    let hybrid = per_group_best(sprob, &fits, &screened);
    if hybrid != screened.p {
        if let Ok(f) = levenberg_marquardt(sprob, screened.spec.clone(), hybrid, SCREEN_ITERATIONS) {
            if f.bic() < screened.bic() {
                screened = f;
            }
        }
    }
    let (screened, screened_sig) = unless_cut_off(sprob, scurrent, ssig, screened);
    let effects = screened.spec.effects.clone();
    // Effects that earn their place only by making the link rigid or its spring vanish fill the
    // gap that bound leaves, and the report warns of such a fit: a combination that takes some
    // temperature's stiffness to or near a bound it was away from is not kept (fresh rig 114:
    // link damping and a 20 mrad backlash on a rigid link in place of the truth's Coulomb friction,
    // which then no refit could reach; rejected, Coulomb friction alone came next, all within 4 %).
    // A damping at its bound is not counted: with link damping in, the transmission's own may
    // rightly go to nothing (fresh rig 125, whose combination that rule would have lost).
    let verdict = combination_verdict(sprob, scurrent, ssig, &screened, &screened_sig);
    let mut attempt = CombinationAttempt { stage, effects, removed: vec![], verdict };
    debug(format_args!(
        "combination {:?} screened in {:?}: kept {}",
        attempt.effects,
        t.elapsed(),
        attempt.verdict.keep
    ));
    if !attempt.verdict.keep {
        return Some((attempt, None));
    }
    // an effect the screening shows below the noise goes before the long fit on every sample (the
    // combination is judged without it; the backward check would drop it, if the budget let it)
    let hidden = below_noise(sprob, &screened, screened_sig.noise_floor);
    if !hidden.is_empty() {
        debug(format_args!("combination: {hidden:?} below the noise floor, refitted without"));
    }
    let done = if screen.is_some() || !hidden.is_empty() {
        let (spec, p) = spec_without(&screened, prob.n_groups, &hidden);
        // without a screen the screened fit is on every sample: it stands, the hidden effects in
        // for the backward check (fresh rig 802: a combination 670 000 below the baseline in BIC
        // was lost when its refit without link damping ran out of time)
        refit_or_stand(prob, spec, p, screen.is_none().then_some(screened))?
    } else {
        screened
    };
    attempt.effects = done.spec.effects.clone();
    let s = signatures(prob, &done);
    attempt.verdict = combination_verdict(prob, current, sig, &done, &s);
    let accepted = attempt.verdict.keep.then_some((done, s));
    Some((attempt, accepted))
}

/// `spec` at `p` refitted on every sample to convergence; where the refit cannot take a step (the
/// budget ran out), `stands`, a fit already on every sample, is the best model found. None when
/// neither is there.
pub fn refit_or_stand(prob: &Problem, spec: ModelSpec, p: Vec<f64>, stands: Option<Fit>) -> Option<Fit> {
    levenberg_marquardt(prob, spec, p, MAX_ITERATIONS).ok().or(stands)
}

/// Starting points for refitting `current` with the candidates' effects added: the current
/// transmission (the table's for a group at a bound or dragging, where `replace_no_start`) and the
/// closed-form one (the transmission fitted without an effect may have absorbed it: friction
/// mimicked by a softer, more damped link; gravity by a rigid one), each with the linearised effect
/// values and with the effects' typical sizes (a linearisation at a rigid or bounded fit can be
/// absurd); and the equation error with the effects' torques as regressors
/// (transmission and effects estimated together, so neither absorbs the other).
fn candidate_starts(
    prob: &Problem,
    current: &[f64],
    added: &[&Ranked<Effect>],
    law: DampingLaw,
    replace_no_start: bool,
) -> Vec<Vec<f64>> {
    let n_t = 2 * prob.n_groups;
    let closed = prob.closed_form_start(law);
    let linearised: Vec<f64> = added.iter().flat_map(|c| c.start.iter().copied()).collect();
    let typical: Vec<f64> = added
        .iter()
        .flat_map(|c| match c.effect.started_from_ranking_only() {
            true => c.start.clone(),
            false => c.effect.params().iter().map(|p| p.1).collect(),
        })
        .collect();
    // An effect started from the ranking only starts as well where the ranking's projection moves
    // the current parameters with it: K and C fitted without a lag took in the offset the lag
    // makes, and from the current ones a long lag's refit can take more iterations than a
    // screening refit has (an 8 s lag on 8 s heating runs: still above the model without it
    // after four).
    let moved: Option<Vec<f64>> = match added {
        [c] if c.effect.started_from_ranking_only() && c.moved.len() == current.len() => {
            let mut q: Vec<f64> = current.iter().zip(&c.moved).map(|(a, b)| a + b).collect();
            q.extend_from_slice(&linearised);
            Some(q)
        }
        _ => None,
    };
    let table = prob.table_start();
    // a group whose transmission stopped at a bound, or drags the link through its damper, starts
    // from the table's: that is where the structure without the effect went (K → 0 dragging the
    // link like friction, or a rigid link under gravity), and that start would win every
    // comparison of starts by cost (campaign rig 22; fresh rigs 92 and 114, K 100× low off the bound)
    let mut here = current[..n_t].to_vec();
    for g in (0..prob.n_groups).filter(|&g| replace_no_start && no_start(prob, g, current)) {
        here[2 * g..2 * g + 2].copy_from_slice(&table[2 * g..2 * g + 2]);
    }
    let mut starts = Vec::new();
    for transmission in [&here[..], &closed[..]] {
        let distinct = if typical == linearised { 1 } else { 2 };
        for effect in [&linearised, &typical].into_iter().take(distinct) {
            let mut q = transmission.to_vec();
            q.extend_from_slice(&current[n_t..]);
            q.extend_from_slice(effect);
            starts.push(q);
        }
    }
    starts.extend(moved);
    let effects: Vec<Effect> = added.iter().map(|c| c.effect).collect();
    if let Some(e) = prob.equation_error(law, &effects).filter(|e| e.repaired.is_empty()) {
        let mut q = e.p[..n_t].to_vec();
        q.extend_from_slice(&current[n_t..]);
        q.extend_from_slice(&e.p[n_t..]);
        starts.push(q);
    }
    starts
}

/// With a Stribeck excess in `spec`: the best of `starts` by cost, and it again with the excess's
/// velocity at each of `diagnose::stribeck_velocity_grid`'s, every one to be fitted
/// (`fit_from_each`). Where the link sticks and slips, the cost at a start says little of the
/// valley it leads to: fresh rig 655's excess (0.20 N·m over 0.058 rad/s beside 0.46 N·m of Coulomb
/// friction) refitted from the ranking's 0.059 N·m over 0.082 rad/s stopped 31 000 in BIC above
/// the truth's fit, which starts at 0.056 or 0.17 rad/s found. None without the excess. Five
/// refits for one, so only in the search run again (`DeviceRig::velocity_grid`).
fn stribeck_velocity_starts(
    prob: &Problem,
    sprob: &Problem,
    spec: &ModelSpec,
    starts: Vec<Vec<f64>>,
) -> Option<Vec<Vec<f64>>> {
    let o = spec.offset_of(Effect::StribeckFriction, prob.n_groups)?;
    let best = best_start(sprob, spec, starts)?;
    let mut each = vec![best.clone()];
    for v in super::diagnose::stribeck_velocity_grid(prob) {
        let mut q = best.clone();
        q[o + 1] = v.ln();
        each.push(q);
    }
    Some(each)
}

/// The effects whose levels the candidates split per direction (`Effect::levels_over`) that
/// neither the model's `effects` nor the candidates hold, as candidates started at zero.
fn levels_lacking(effects: &[Effect], added: &[&Ranked<Effect>]) -> Vec<Ranked<Effect>> {
    let mut lacking: Vec<Ranked<Effect>> = Vec::new();
    for &e in added.iter().flat_map(|c| c.effect.levels_over()) {
        let held = effects.contains(&e) || added.iter().any(|c| c.effect == e) || lacking.iter().any(|b| b.effect == e);
        if !held {
            lacking.push(Ranked {
                effect: e,
                score: 0.0,
                predicted_delta_bic: 0.0,
                start: vec![0.0; e.params().len()],
                moved: Vec::new(),
                evidence: String::new(),
            });
        }
    }
    lacking
}

/// `current`'s parameters with the effects of `added` appended off: their levels at zero, their
/// time or speed scales (the `ln_` parameters, which no level-zero fit can place) at the ranking's
/// starts. The model these parameters make is `current`'s.
fn off(current: &[f64], added: &[&Ranked<Effect>]) -> Vec<f64> {
    let mut q = current.to_vec();
    for c in added {
        q.extend(c.effect.params().iter().zip(&c.start).map(|(p, &s)| if p.0.starts_with("ln_") { s } else { 0.0 }));
    }
    q
}

/// `best`'s parameters with each temperature group's [ln K, ln C] taken from the fit in `fits`
/// whose residual on that group's runs is smallest.
fn per_group_best(prob: &Problem, fits: &[Fit], best: &Fit) -> Vec<f64> {
    let lengths = prob.lengths();
    let group_sse = |f: &Fit| {
        let mut sse = vec![0.0; prob.n_groups];
        let mut offset = 0;
        for (r, &n) in lengths.iter().enumerate() {
            sse[prob.group[r]] += f.residual[offset..offset + n].iter().map(|e| e * e).sum::<f64>();
            offset += n;
        }
        sse
    };
    let sses: Vec<Vec<f64>> = fits.iter().map(group_sse).collect();
    let mut p = best.p.clone();
    for g in 0..prob.n_groups {
        if let Some(i) = (0..fits.len()).min_by(|&a, &b| sses[a][g].total_cmp(&sses[b][g])) {
            p[2 * g..2 * g + 2].copy_from_slice(&fits[i].p[2 * g..2 * g + 2]);
        }
    }
    p
}

/// The problem, fit and signatures to screen on: the screening share when there is one, else
/// the whole problem with `current`.
fn screened<'s, 'a>(
    screen: &'s Option<(Problem<'a>, Fit, Signatures)>,
    prob: &'s Problem<'a>,
    current: &'s Fit,
    sig: &'s Signatures,
) -> (&'s Problem<'a>, &'s Fit, &'s Signatures) {
    match screen {
        Some((sp, sc, ss)) => (sp, sc, ss),
        None => (prob, current, sig),
    }
}

/// Re-evaluates the screening share at `current` (after `current` changed).
fn refresh_screen(screen: &mut Option<(Problem, Fit, Signatures)>, current: &Fit) {
    if let Some((sp, sc, ss)) = screen.as_mut() {
        if let Some(f) = Fit::evaluate_with_jacobian(sp, current.spec.clone(), current.p.clone()) {
            *ss = signatures(sp, &f);
            *sc = f;
        }
    }
}

/// A damping law and a spring-bank share: the structure choices the data decide between.
pub type Structure = (DampingLaw, SpringBank);

/// The structures the data allow (the first is the default), and why.
pub struct LawChoice {
    pub allowed: Vec<Structure>,
    pub reason: String,
    /// Sinusoidal runs at one frequency per temperature: the laws fit alike, held-out runs at
    /// other frequencies may decide.
    pub undecided: bool,
}

impl LawChoice {
    /// The structures a candidate's refit tries beside the current one: every allowed law on the
    /// current spring bank. A law can stand in for an effect (Coulomb friction's loss per cycle falls
    /// with frequency as hysteretic damping's does), so each candidate is refitted under every law.
    /// The bank (the shape of K and C within a heating run) is chosen again after each round's winner
    /// and with the final effects, with the effects in: refitting every candidate on both banks as
    /// well doubled a drifting rig's refits (campaign rig 297, a 7.9 K drift, ran out of its budget
    /// before its first round). Choosing the bank at the baseline alone was tried and not kept: rig
    /// 288's baseline took the nominal bank by 61 of BIC, and with its friction in the scaled bank won
    /// by 4 000.
    pub fn on_bank(&self, current: Structure) -> Vec<Structure> {
        std::iter::once(current)
            .chain(self.allowed.iter().copied().filter(|&s| s != current && s.1 == current.1))
            .collect()
    }
}

/// The same effects under the other allowed laws, refitted from `fit`'s values: the better law by
/// BIC (equal parameter counts: the lower error). Rows (stage, law, rmse, bic) for the report.
fn best_law(
    prob: &Problem,
    screen: Option<&Problem>,
    fit: Fit,
    laws: &[Structure],
    stage: &str,
    rows: &mut Vec<LawRow>,
) -> Fit {
    let mut best = fit;
    let first = (best.spec.law, best.spec.springs);
    rows.push(LawRow { stage: stage.into(), structure: first, rmse: best.rmse(), bic: best.bic() });
    // screened on the start of the runs when a screening problem is given, else on all of them
    let sprob = screen.unwrap_or(prob);
    let Some(best_screened) = Fit::evaluate(sprob, best.spec.clone(), best.p.clone()) else { return best };
    for &(law, springs) in laws.iter().filter(|&&l| l != first) {
        let spec = ModelSpec { effects: best.spec.effects.clone(), law, springs, elasto_backlash: false };
        // from the other structure's optimum, and from this law's closed-form transmission with
        // the effects' values (a transmission fitted under the wrong law is a poor start)
        let n_t = 2 * prob.n_groups;
        let mut starts = vec![best.p.clone()];
        if best.spec.effects.is_empty() {
            starts.extend(baseline_starts(prob, law).into_iter().map(|s| s.1));
        } else {
            let mut q = prob.closed_form_start(law);
            q.extend_from_slice(&best.p[n_t..]);
            starts.push(q);
        }
        // screened first; only a structure that already wins is run to convergence on every sample
        let Ok(screened) = fit_from_best(sprob, spec.clone(), starts, SCREEN_ITERATIONS) else { continue };
        let wins = screened.bic() < best_screened.bic();
        let other = if wins && (screen.is_some() || screened.iterations >= SCREEN_ITERATIONS) {
            levenberg_marquardt(prob, spec, screened.p.clone(), MAX_ITERATIONS).ok()
        } else if screen.is_none() {
            Some(screened)
        } else {
            Fit::evaluate(prob, spec, screened.p.clone())
        };
        let Some(other) = other else { continue };
        rows.push(LawRow { stage: stage.into(), structure: (law, springs), rmse: other.rmse(), bic: other.bic() });
        if other.bic() < best.bic() {
            best = other;
        }
    }
    best
}

/// A Maxwell branch at its shortest relaxation time (1 ms, the fit's bound) relaxes faster than any
/// motion the fit lets it show: in the runs' band its torque K_m τ φ' is the transmission's damping,
/// the same form with two parameters more. Fresh rig 617 (a multisine, no Maxwell branch in its
/// truth) kept one at K_m 19.2 N·m/rad and τ = 1 ms beside C 0.175 N·m·s/rad, where the truth's C
/// is 0.195 = 0.175 + K_m τ. The branch goes, K_m τ joins each group's damping (exact under the
/// viscous law; under the hysteretic law, whose C is read at a reference frequency, only a start) and
/// the rest is refitted from there; None where the model has no branch at that bound or the refit fails.
fn maxwell_as_damping(prob: &Problem, fit: &Fit) -> Option<(Fit, super::stepwise::Pruned<Effect>)> {
    let maxwell = Effect::FrequencyDependentModulus;
    let o = fit.spec.offset_of(maxwell, prob.n_groups)?;
    let shortest = maxwell.params()[1].2?;
    if fit.p[o + 1] > shortest + 1e-9 {
        return None;
    }
    let damper = fit.p[o] * fit.p[o + 1].exp();
    let (spec, mut p) = spec_without(fit, prob.n_groups, &[maxwell]);
    for g in 0..prob.n_groups {
        p[2 * g + 1] = (p[2 * g + 1].exp() + damper).ln();
    }
    let refit = levenberg_marquardt(prob, spec, p, MAX_ITERATIONS).ok()?;
    let pruned = super::stepwise::Pruned {
        effect: maxwell,
        replaced_by: None,
        bic_with: fit.bic(),
        bic_without: refit.bic(),
        below_noise: false,
        because: Some(format!(
            "it sat at its shortest relaxation time ({:.0e} s), where in these runs' band it is transmission \
             damping of {damper:.3e} N·m·s/rad, which joined C",
            shortest.exp()
        )),
    };
    Some((refit, pruned))
}

/// The structures the final effects are refitted under: every allowed one where `affords` (refits,
/// two starts for each structure but the current) says the budget holds them, else the damping laws
/// under the current spring bank alone, else none.
fn final_structures(laws: &LawChoice, current: Structure, affords: impl Fn(f64) -> bool) -> Option<Vec<Structure>> {
    [laws.allowed.clone(), laws.on_bank(current)]
        .into_iter()
        .find(|s| s.len() > 1 && affords(2.0 * (s.len() as f64 - 1.0)))
}

/// One comparison of damping laws.
#[derive(Clone, Debug)]
pub struct LawRow {
    pub stage: String,
    pub structure: Structure,
    pub rmse: f64,
    pub bic: f64,
}

/// Whether a run's moving start earns its one more number: the run's BIC, from its sums of squares at
/// rest and moving over `n` samples, falls by more than `BIC_MARGIN`.
fn moving_start_earns(n: usize, sse_at_rest: f64, sse_moving: f64) -> bool {
    let n = n as f64;
    n * (sse_at_rest / sse_moving).ln() > n.ln() + BIC_MARGIN
}

/// The runs started at rest whose estimated initial speed the final model prefers, each judged on
/// its own at the model's parameters (its BIC must fall by `BIC_MARGIN`), then one refit if any
/// run changed. No refit comes first, so the comparison does not lean towards the moving starts.
fn restart_moving_runs(prob: &mut Problem, current: Fit, estimated: &[f64]) -> Fit {
    let before = prob.initial_speeds();
    let candidates: Vec<usize> = (0..estimated.len()).filter(|&r| estimated[r] != 0.0 && before[r] == 0.0).collect();
    prob.set_initial_speeds(estimated);
    let moving = prob.outputs(&current.spec, &current.p).map(|o| prob.residual(&o));
    prob.set_initial_speeds(&before);
    let Some(moving) = moving else { return current };
    let lengths = prob.lengths();
    let (at_rest, moving) = (prob.run_sse(&current.residual), prob.run_sse(&moving));
    let mut changed = false;
    for &r in &candidates {
        debug(format_args!("run {r}: at rest SSE {:.4e}, moving {:.4e}", at_rest[r], moving[r]));
        if moving_start_earns(lengths[r], at_rest[r], moving[r]) {
            prob.inputs[r].initial_link_speed = estimated[r];
            changed = true;
        }
    }
    debug(format_args!("restarted moving: {:?}", prob.initial_speeds()));
    if !changed {
        return current;
    }
    levenberg_marquardt(prob, current.spec.clone(), current.p.clone(), MAX_ITERATIONS).unwrap_or_else(|_| {
        // (out of time) the runs start as `current` was fitted with
        prob.set_initial_speeds(&before);
        current
    })
}

/// Runs started moving (`conditioning::initial_speed` saw the link moving at its first sample) are
/// fitted again at rest with `fit`'s structure; a run keeps the moving start only when it lowers
/// that run's BIC by more than `BIC_MARGIN` (one more number per run). A link that starts at rest
/// and catches up with the motor within a millisecond looks moving over the estimator's window,
/// so the model decides: once with the baseline, and again with the final model for the runs
/// still moving. Returns the fit refitted with the chosen starts.
pub fn resolve_initial_speeds(prob: &mut Problem, moving: Fit) -> Fit {
    let speeds = prob.initial_speeds();
    // only runs that start their file are tried at rest: a segment after a gap is moving, and its
    // speed is fitted (`fit_initial_speeds`); at rest it would pull the parameters every other run
    // is judged with (campaign seed 88: a segment at 11 rad/s set to rest left the file-starting
    // runs 30x worse at rest than with a wrong speed of -0.45 rad/s, so that speed was kept)
    let judged: Vec<bool> = prob.inputs.iter().zip(&speeds).map(|(i, &v)| v != 0.0 && !i.after_gap).collect();
    if !judged.iter().any(|&j| j) {
        return moving;
    }
    let at_rest: Vec<f64> = speeds.iter().zip(&judged).map(|(&v, &j)| if j { 0.0 } else { v }).collect();
    prob.set_initial_speeds(&at_rest);
    let Ok(resting) = levenberg_marquardt(prob, moving.spec.clone(), moving.p.clone(), MAX_ITERATIONS) else {
        prob.set_initial_speeds(&speeds);
        return moving;
    };
    let lengths = prob.lengths();
    let (sm, sr) = (prob.run_sse(&moving.residual), prob.run_sse(&resting.residual));
    debug(format_args!("initial speeds {speeds:?}: sse moving {sm:?}, at rest {sr:?}"));
    let mut kept = 0;
    for (r, inp) in prob.inputs.iter_mut().enumerate() {
        if judged[r] && moving_start_earns(lengths[r], sr[r], sm[r]) {
            inp.initial_link_speed = speeds[r];
            kept += 1;
        }
    }
    if kept == 0 {
        return resting;
    }
    if kept == judged.iter().filter(|&&j| j).count() {
        return moving;
    }
    let start = if resting.sse < moving.sse { resting.p.clone() } else { moving.p.clone() };
    levenberg_marquardt(prob, moving.spec.clone(), start, MAX_ITERATIONS).unwrap_or_else(|_| {
        // (out of time) the runs start as `moving` was fitted with
        prob.set_initial_speeds(&speeds);
        moving
    })
}

/// Gauss–Newton steps on the initial speeds (the model is linear in them but for its friction).
const INITIAL_SPEED_STEPS: usize = 3;
/// Passes of (initial speeds at fixed parameters, then the parameters at those speeds).
const INITIAL_SPEED_PASSES: usize = 4;

/// The initial link speed of every segment after a gap (`SimInput::after_gap`), fitted with
/// `fit`'s parameters: a segment's start moves only that segment, so one batch of simulations
/// serves every segment's Gauss–Newton step. A speed is kept where it lowers the segment's BIC
/// against a start at rest by `BIC_MARGIN` (one more number per segment). The window estimate
/// (`conditioning::initial_speed`) cannot see a speed below three times its standard error: on a
/// noisy encoder that leaves the link's own swing after the gap, lightly damped, in the residual
/// (campaign rig 43: 0.28 rad/s missed, a 0.025 rad transient at the 1.2 Hz natural frequency).
/// A run that starts its file keeps the window's estimate, judged by `resolve_initial_speeds`: fitted
/// freely, its speed would stand in for an effect the model still lacks (measured on campaign rigs
/// 1, 13, 23 and 30, which start at rest: two of them lost their friction).
///
/// Each pass takes one Gauss–Newton step on the parameters and the speeds together, then refits
/// the parameters at the new speeds; passes go on while the BIC falls by more than `BIC_MARGIN`.
/// Speeds alone, then parameters alone, answer each other's pull a little at a time: on rig 43's
/// 60 °C run the other segment's start, wrong, had pulled C to 0.169 (truth 0.122), and four such
/// alternations left 0.129; with the joint step, 0.124.
pub fn fit_initial_speeds(prob: &mut Problem, fit: Fit) -> Fit {
    let free: Vec<bool> = prob.inputs.iter().map(|i| i.after_gap).collect();
    initial_speeds_passes(prob, fit, &free)
}

/// [`fit_initial_speeds`] for the segments after a gap and every run that starts its file moving,
/// once the effects are settled: a moving start's window estimate is a quadratic's slope, biased
/// by how the motion curves over 20 ms, and never fitted before (free during the search, it stood in
/// for friction the model did not yet have, above). A run that starts at rest stays at rest. A
/// 0.1 rad/s start at mid-swing read 0.06–0.09 rad/s and left 2.8× the floor and a residual
/// flagged as structure, every parameter right (a truth-model rig of this session's; at 0.1 rad/s,
/// 1.0×). Where no file starts moving, `fit` as it is: the segments after gaps alone were fitted
/// before ([`fit_initial_speeds`]), and fitting them again would only repeat that.
pub fn fit_moving_starts(prob: &mut Problem, fit: Fit) -> Fit {
    if !prob.inputs.iter().any(|i| i.initial_link_speed != 0.0) {
        return fit;
    }
    let free: Vec<bool> = prob.inputs.iter().map(|i| i.after_gap || i.initial_link_speed != 0.0).collect();
    initial_speeds_passes(prob, fit, &free)
}

fn initial_speeds_passes(prob: &mut Problem, mut fit: Fit, free: &[bool]) -> Fit {
    if !free.iter().any(|&f| f) {
        return fit;
    }
    for _ in 0..INITIAL_SPEED_PASSES {
        let before = fit.bic();
        fit = initial_speeds_pass(prob, fit, free);
        if fit.bic() > before - BIC_MARGIN {
            break;
        }
    }
    fit
}

/// One pass of `fit_initial_speeds`.
fn initial_speeds_pass(prob: &mut Problem, fit: Fit, free: &[bool]) -> Fit {
    let lengths = prob.lengths();
    let offsets: Vec<usize> = lengths.iter().scan(0, |o, &n| Some(std::mem::replace(o, *o + n))).collect();
    let residual_at = |prob: &mut Problem, p: &[f64], speeds: &[f64]| -> Option<Vec<f64>> {
        prob.set_initial_speeds(speeds);
        prob.outputs(&fit.spec, p).map(|o| prob.residual(&o))
    };
    let before = prob.initial_speeds();
    // a step the size of the run's mean speed over its swing, at least
    let scale: Vec<f64> = prob
        .measured
        .iter()
        .zip(&prob.inputs)
        .map(|(y, i)| {
            let swing =
                y.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b)) - y.iter().fold(f64::INFINITY, |a, &b| a.min(b));
            let span = i.time[i.time.len() - 1] - i.time[0];
            (swing / span.max(1e-300)).max(1e-9)
        })
        .collect();
    let probe_of = |speeds: &[f64]| -> Vec<f64> {
        (0..speeds.len())
            .map(|r| if free[r] { speeds[r] + 1e-3 * scale[r].max(speeds[r].abs()) } else { speeds[r] })
            .collect()
    };
    let (mut p, mut speeds, mut residual) = (fit.p.clone(), before.clone(), fit.residual.clone());
    // first one Gauss–Newton step on the parameters and the speeds together (alone, each answers
    // the other's pull a little at a time)
    let probe = probe_of(&speeds);
    if let Some(moved) = residual_at(prob, &p, &probe) {
        let h: Vec<f64> = probe.iter().zip(&speeds).map(|(a, b)| a - b).collect();
        if let Some((q, v, r)) = joint_step(prob, &fit, &speeds, &h, &moved, &offsets, &lengths, &residual_at) {
            (p, speeds, residual) = (q, v, r);
        }
    }
    for _ in 0..INITIAL_SPEED_STEPS {
        let probe = probe_of(&speeds);
        let Some(moved) = residual_at(prob, &p, &probe) else { break };
        let trial: Vec<f64> = (0..lengths.len())
            .map(|r| {
                if !free[r] {
                    return speeds[r];
                }
                let (o, n, h) = (offsets[r], lengths[r], probe[r] - speeds[r]);
                let (mut gg, mut gr) = (0.0, 0.0);
                for k in o..o + n {
                    let g = (moved[k] - residual[k]) / h;
                    gg += g * g;
                    gr += g * residual[k];
                }
                if gg > 0.0 {
                    speeds[r] - gr / gg
                } else {
                    speeds[r]
                }
            })
            .collect();
        let Some(tried) = residual_at(prob, &p, &trial) else { break };
        let (now, then) = (prob.run_sse(&residual), prob.run_sse(&tried));
        let better: Vec<bool> = now.iter().zip(&then).map(|(a, b)| b < a).collect();
        if !better.iter().any(|&b| b) {
            break;
        }
        for r in 0..lengths.len() {
            if better[r] {
                speeds[r] = trial[r];
                residual[offsets[r]..offsets[r] + lengths[r]]
                    .copy_from_slice(&tried[offsets[r]..offsets[r] + lengths[r]]);
            }
        }
    }
    let rest_speeds: Vec<f64> = (0..lengths.len()).map(|r| if free[r] { 0.0 } else { speeds[r] }).collect();
    let Some(resting) = residual_at(prob, &p, &rest_speeds) else {
        prob.set_initial_speeds(&before);
        return fit;
    };
    let (fitted, rest) = (prob.run_sse(&residual), prob.run_sse(&resting));
    let chosen: Vec<f64> =
        (0..lengths.len())
            .map(|r| {
                if !free[r] || moving_start_earns(lengths[r], rest[r], fitted[r].max(1e-300)) {
                    speeds[r]
                } else {
                    0.0
                }
            })
            .collect();
    prob.set_initial_speeds(&chosen);
    debug(format_args!("fitted initial speeds: {before:?} → {chosen:?}"));
    if chosen == before {
        return fit;
    }
    match levenberg_marquardt(prob, fit.spec.clone(), p, MAX_ITERATIONS) {
        Ok(f) if f.sse < fit.sse => f,
        _ => {
            prob.set_initial_speeds(&before);
            fit
        }
    }
}

/// One Gauss–Newton step on `fit`'s parameters and the runs' initial speeds together, from
/// `fit.jacobian` and each run's speed sensitivity (`moved`: the residual with every speed moved by
/// its `h`, 0 for a speed that stays; a run's speed moves only that run's rows), halved up to twice until the sum of squares
/// falls. The parameters stay within their bounds. Returns (parameters, speeds, residual).
#[allow(clippy::too_many_arguments)]
fn joint_step(
    prob: &mut Problem,
    fit: &Fit,
    speeds: &[f64],
    h: &[f64],
    moved: &[f64],
    offsets: &[usize],
    lengths: &[usize],
    residual_at: &impl Fn(&mut Problem, &[f64], &[f64]) -> Option<Vec<f64>>,
) -> Option<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    let (n, np, nr) = (fit.residual.len(), fit.p.len(), speeds.len());
    if fit.jacobian.nrows() != n || fit.jacobian.ncols() != np || moved.len() != n {
        return None;
    }
    let mut a = DMatrix::<f64>::zeros(n, np + nr);
    a.columns_mut(0, np).copy_from(&fit.jacobian);
    for r in (0..nr).filter(|&r| h[r] != 0.0) {
        for k in offsets[r]..offsets[r] + lengths[r] {
            // ∂ŷ/∂v = −∂(y − ŷ)/∂v
            a[(k, np + r)] = -(moved[k] - fit.residual[k]) / h[r];
        }
    }
    // columns scaled to unit norm: speeds and log-parameters differ by orders of magnitude
    let norms: Vec<f64> = a.column_iter().map(|c| c.norm()).collect();
    for (j, &s) in norms.iter().enumerate() {
        if s > 0.0 {
            a.column_mut(j).scale_mut(1.0 / s);
        }
    }
    let svd = a.svd(true, true);
    let tol = 1e-10 * svd.singular_values.max();
    let delta = svd.solve(&DVector::from_column_slice(&fit.residual), tol).ok()?;
    let delta: Vec<f64> = delta.iter().zip(&norms).map(|(d, &s)| if s > 0.0 { d / s } else { 0.0 }).collect();
    let (lower, upper) = prob.bounds(&fit.spec);
    let mut step = 1.0;
    for _ in 0..3 {
        let q: Vec<f64> = (0..np)
            .map(|j| {
                let x = fit.p[j] + step * delta[j];
                let x = lower[j].map_or(x, |l| x.max(l));
                upper[j].map_or(x, |u| x.min(u))
            })
            .collect();
        let v: Vec<f64> = (0..nr).map(|r| speeds[r] + step * delta[np + r]).collect();
        if let Some(res) = residual_at(prob, &q, &v) {
            if res.iter().map(|e| e * e).sum::<f64>() < fit.sse {
                return Some((q, v, res));
            }
        }
        step *= 0.5;
    }
    None
}

/// Simulations run so far (for `debug`).
fn sims(prob: &Problem) -> usize {
    prob.sim.simulations.load(std::sync::atomic::Ordering::Relaxed)
}

/// RMSE on the second half of every run of the model refitted (from `fit`) on the first halves:
/// a blocked fold that respects time (the second half is predicted by simulating on from the
/// start, never fitted).
pub fn blocked_fold_rmse(prob: &Problem, fit: &Fit) -> Result<f64, String> {
    let first = prob.truncated(0.5);
    let refit = levenberg_marquardt(&first, fit.spec.clone(), fit.p.clone(), MAX_ITERATIONS)?;
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
pub fn damping_laws(prob: &Problem) -> LawChoice {
    use super::fit::DampingLaw::{Hysteretic, Viscous};
    use super::fit::SpringBank::{Nominal, Scaled};
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
    let banks = if super::diagnose::thermocouple_varies(prob) {
        reason += "; the thermocouple moves within runs, so the spring bank is fitted two ways (scaled with the PCL, \
                   or nominal with the PCL carrying the rest) and the lower BIC kept (baseline, after each round and \
                   with the final effects; a candidate's refit keeps the current bank)";
        vec![Scaled, Nominal]
    } else {
        reason += "; the thermocouple is steady within runs, so the split of K between springs and PCL cannot show \
                   (springs scaled with the PCL)";
        vec![Scaled]
    };
    let allowed = laws.iter().flat_map(|&l| banks.iter().map(move |&b| (l, b))).collect();
    LawChoice { allowed, reason, undecided: sinusoidal && !two_frequencies }
}

/// A device model in the search: the fit and its residual's signatures.
#[derive(Clone, Debug)]
pub struct Judged {
    pub fit: Fit,
    pub sig: Signatures,
}

/// The device as a rig of the one search (`stepwise`): runs driven by the measured motor angle,
/// the transmission fitted per temperature under the damping law and spring share the data
/// allow. Candidates are ranked and screened on the start of every run when that holds enough
/// cycles (the winner is judged on every sample); an effect earns its place by BIC and by the
/// structure it removes from the residual.
pub struct DeviceRig<'p, 'a> {
    prob: &'p Problem<'a>,
    laws: &'p LawChoice,
    screen: std::cell::RefCell<Option<(Problem<'a>, Fit, Signatures)>>,
    rows: std::cell::RefCell<Vec<LawRow>>,
    /// (structure, effects) the equation error's combinations refitted already.
    refitted: std::cell::RefCell<Vec<(Structure, Vec<Effect>)>>,
    /// (model's effects, its BIC's bits, effect) whose absence showed (`Rig::absence_shows`).
    absence_shown: std::cell::RefCell<Vec<(Vec<Effect>, u64, Effect)>>,
    /// A Stribeck excess refitted from every velocity of the grid too (`stribeck_velocity_starts`)
    /// where the model sits far above its floor: only in the search run again, which the first one
    /// left with structure. In every search it cost 30 % more wall time on fresh seeds 651–690 (sum
    /// 794 → 1 033 s, one budget-bound rig worse) for one rig gained, 655, which needs both.
    velocity_grid: bool,
}

impl DeviceRig<'_, '_> {
    /// An effect `prob`'s runs cannot show, which the ranking lists unprobed and no refit brings in:
    /// a Maxwell branch on sinusoids at one frequency per temperature (`diagnose::MAXWELL_UNSEEN`), a
    /// thermal lag behind a thermocouple that holds still (the lag's refit only adds its parameter:
    /// campaign rig 287 spent three refits on it).
    fn unseen(&self, prob: &Problem, e: Effect) -> bool {
        match e {
            Effect::FrequencyDependentModulus => self.laws.undecided,
            Effect::ThermalLag => !super::diagnose::thermocouple_varies(prob),
            _ => false,
        }
    }

    /// The problem, fit and signatures to screen `m` on.
    fn with_screen<T>(&self, m: &Judged, f: impl FnOnce(&Problem, &Fit, &Signatures) -> T) -> T {
        let screen = self.screen.borrow();
        let (p, c, s) = screened(&screen, self.prob, &m.fit, &m.sig);
        f(p, c, s)
    }

    /// `m` without the effects `drop`, with the candidates `added` (and without what they take the
    /// place of, `Effect::takes_place_of`: both in at once would be one column twice), refitted on
    /// the screening share from `m`'s values (`candidate_starts`).
    /// A single candidate (`as_single`) is refitted under every structure the data allow; otherwise
    /// (several candidates, or a step judged as a pair is) under the current structure. Capped
    /// either way: the search runs on a single the cap cut off (`stepwise::run_on_cut_off`).
    fn screened_refit(
        &self,
        m: &Judged,
        drop: &[Effect],
        added: &[&Ranked<Effect>],
        as_single: bool,
    ) -> Option<Judged> {
        let drop: Vec<Effect> =
            drop.iter().copied().chain(added.iter().filter_map(|c| c.effect.takes_place_of())).collect();
        let (mut spec, p) = spec_without(&m.fit, self.prob.n_groups, &drop);
        // the levels a candidate splits per direction come in with it where the model lacks them
        // (fresh rigs 1195, 1199 and 1201: asymmetric friction over Coulomb friction alone, its
        // viscous levels at 0 and the link's drag taken by C, +14 to +117 %)
        let base = levels_lacking(&spec.effects, added);
        let single = as_single && added.len() == 1;
        let added: Vec<&Ranked<Effect>> = base.iter().chain(added.iter().copied()).collect();
        let added = &added[..];
        spec.effects.extend(added.iter().map(|c| c.effect));
        // What the runs cannot show is never refitted, alone, in a pair or in a swap (the ranking
        // lists it unprobed): its refit could only stand in for something else, or cost time for nothing.
        if added.iter().any(|c| self.unseen(self.prob, c.effect)) {
            return None;
        }
        // A law chosen without the effect may be standing in for it (Coulomb friction's dissipation
        // per cycle falls with frequency as hysteretic damping's does; campaign rig 180): a single
        // candidate is refitted under every structure the data allow, and the lowest BIC is its refit.
        // Under every one, not only where it fails to earn its place under the current one: on rig 38
        // a Stribeck excess earned its place under the stand-in law and kept a link damping beside it.
        let any_no_start = (0..self.prob.n_groups).any(|g| no_start(self.prob, g, &p));
        let takes_nothing_out = !drop.iter().any(|e| m.fit.spec.effects.contains(e));
        let structures: Vec<Structure> =
            if single { self.laws.on_bank((spec.law, spec.springs)) } else { vec![(spec.law, spec.springs)] };
        self.with_screen(m, |sprob, current, current_sig| {
            let t = std::time::Instant::now();
            let screened = structures
                .iter()
                .filter_map(|&(law, springs)| {
                    let spec = ModelSpec { law, springs, ..spec.clone() };
                    // the starts Levenberg–Marquardt runs from: the best by cost, or it at each
                    // Stribeck velocity
                    let chosen = |replace| {
                        let starts = candidate_starts(self.prob, &p, added, law, replace);
                        let with_excess = spec.effects.contains(&Effect::StribeckFriction);
                        if self.velocity_grid && with_excess && far_above_floor(current_sig) {
                            stribeck_velocity_starts(self.prob, sprob, &spec, starts)
                        } else {
                            best_start(sprob, &spec, starts).map(|p0| vec![p0])
                        }
                    };
                    let fit = |each: Vec<Vec<f64>>| fit_from_each(sprob, &spec, each, SCREEN_ITERATIONS).ok();
                    let table_starts = chosen(true);
                    let table = table_starts.clone().and_then(fit);
                    // a transmission on a bound, or dragging, may be where the effect's absence put
                    // it (the table's start then finds the effect's valley) or where the truth has
                    // it (a link damper that took the transmission's damping, rig 185: C → 0): where
                    // the table's start ends above the current model, the current transmission's
                    // start is refitted too, and the lower BIC kept. Where the starts chosen are the
                    // table's again (both lost to a start they share), the fit would repeat to the
                    // digit: fresh rig 1432's gravity, 20 s of its 59 s refit.
                    let here = if any_no_start && table.as_ref().is_none_or(|t| t.bic() >= current.bic()) {
                        chosen(false).filter(|s| Some(s) != table_starts.as_ref()).and_then(fit)
                    } else {
                        None
                    };
                    let best = table.into_iter().chain(here).min_by(|a, b| a.bic().total_cmp(&b.bic()));
                    // The model with the candidates off is the current one, so a refit that ends
                    // above it lost its way from the starts above (a linearised or typical level
                    // far off, a transmission in another valley): on the campaign's samples one
                    // refit in nine ended so, a link damping 83 000 in BIC above the model without
                    // it (rig 276). Under the current structure, and where it takes out no effect
                    // of the current model, it is refitted from the current model with the
                    // candidates' levels at zero, and the lower BIC kept.
                    let nested = takes_nothing_out && (law, springs) == (m.fit.spec.law, m.fit.spec.springs);
                    let lost = nested && best.as_ref().is_none_or(|b| b.bic() >= current.bic());
                    let from_here = lost
                        .then(|| levenberg_marquardt(sprob, spec.clone(), off(&p, added), SCREEN_ITERATIONS).ok())
                        .flatten();
                    best.into_iter().chain(from_here).min_by(|a, b| a.bic().total_cmp(&b.bic()))
                })
                .min_by(|a, b| a.bic().total_cmp(&b.bic()))?;
            // (a single the cap cut off is run on by the search once the round's shortlist is
            // screened, `stepwise::run_on_cut_off`; a pair never is, as a fallback for effects that
            // show only together: run on, two effects find a valley of their own more often than
            // the truth's, measured on campaign rig 23)
            let sig = signatures(sprob, &screened);
            let refit = screened;
            debug(format_args!(
                "refit {:?} (without {drop:?}) took {:?}, {} iterations, BIC {:.1} against {:.1}",
                refit.spec.effects,
                t.elapsed(),
                refit.iterations,
                refit.bic(),
                current.bic()
            ));
            Some(Judged { fit: refit, sig })
        })
    }

    fn judged(&self, prob: &Problem, fit: Fit) -> Judged {
        let sig = signatures(prob, &fit);
        Judged { fit, sig }
    }
}

impl Rig for DeviceRig<'_, '_> {
    type Effect = Effect;
    type Model = Judged;
    type Detail = Evidence;
    type State = Signatures;

    fn name(e: Effect) -> &'static str {
        e.name()
    }
    fn effects(&self, m: &Judged) -> Vec<Effect> {
        m.fit.spec.effects.clone()
    }
    fn effect_count(&self, m: &Judged) -> usize {
        m.fit.spec.reported_effects().len()
    }
    fn bic(&self, m: &Judged) -> f64 {
        m.fit.bic()
    }
    fn structure_left(&self, m: &Judged) -> bool {
        !m.sig.white()
    }
    fn rankable(&self, m: &Judged) -> bool {
        // a transmission dragging the link through its damper is no start either (`no_start`)
        !(0..self.prob.n_groups).any(|g| no_start(self.prob, g, &m.fit.p))
    }
    fn state(&self, m: &Judged) -> Signatures {
        self.with_screen(m, |_, _, s| s.clone())
    }
    fn rank(&self, m: &Judged) -> Vec<Ranked<Effect>> {
        let t = std::time::Instant::now();
        // ranked on the screening share (the linearised projections need no more)
        let out = self.with_screen(m, |p, f, s| rank(p, f, s, |e| self.unseen(p, e)));
        debug(format_args!("rank took {:?}", t.elapsed()));
        out
    }
    fn refit_with(&self, m: &Judged, added: &[&Ranked<Effect>]) -> Option<Judged> {
        self.screened_refit(m, &[], added, true)
    }
    fn refit_beside(&self, m: &Judged, added: &[&Ranked<Effect>]) -> Option<Judged> {
        // judged against the model before `m` (a big BIC gain already in), a single's run-on
        // would take every refit to the iteration cap: rig 144's Stribeck excess, 41 s
        self.screened_refit(m, &[], added, false)
    }
    fn judge(&self, m: &Judged, refit: &Judged) -> Verdict<Evidence> {
        self.with_screen(m, |_, c, s| verdict(c, s, &refit.fit, &refit.sig))
    }
    fn capped(&self, refit: &Judged) -> bool {
        refit.fit.iterations == SCREEN_ITERATIONS
    }
    fn run_on(&self, m: &Judged, refit: Judged) -> Judged {
        self.with_screen(m, |sprob, _, _| {
            let (spec, p) = (refit.fit.spec.clone(), refit.fit.p.clone());
            match levenberg_marquardt(sprob, spec, p, MAX_ITERATIONS) {
                Ok(f) if f.bic() < refit.fit.bic() => {
                    debug(format_args!(
                        "ran on {:?}: {} iterations, BIC {:.1} to {:.1}",
                        f.spec.effects,
                        f.iterations,
                        refit.fit.bic(),
                        f.bic()
                    ));
                    self.judged(sprob, f)
                }
                _ => refit,
            }
        })
    }
    fn converge(&self, m: &Judged, winner: Judged, round: usize) -> Option<Judged> {
        // an effect can change which damping law the data favour (friction read as frequency-
        // dependent loss before it was in): re-chosen on the screening share with it, so only the
        // chosen structure is fitted on every sample
        let screen = self.screen.borrow();
        let f = match &*screen {
            Some((sp, _, _)) => {
                let stage = format!("round {round} (screening share)");
                best_law(sp, None, winner.fit, &self.laws.allowed, &stage, &mut self.rows.borrow_mut())
            }
            None if winner.fit.iterations < SCREEN_ITERATIONS => return Some(winner),
            None => winner.fit,
        };
        // (fresh rig 802, unscreened: a Coulomb refit 134 000 below the baseline in BIC was lost
        // when the budget ended before its run-on's first step, and the report had no effect)
        let (spec, p, screened_sse) = (f.spec.clone(), f.p.clone(), f.sse);
        let done = refit_or_stand(self.prob, spec, p, screen.is_none().then_some(f))?;
        // the winner's SSE is over the screening share when there is one; done's over every sample
        let share = if screen.is_some() { " (screening share)" } else { "" };
        debug(format_args!(
            "winner {} iterations on every sample: SSE {screened_sse:.6e}{share}, then {:.6e} (every sample)",
            done.iterations, done.sse
        ));
        let s = signatures(self.prob, &done);
        earns_its_place(&m.fit, &m.sig, &done, &s).then_some(Judged { fit: done, sig: s })
    }
    fn partly_earned(&self, m: &Judged, v: &Verdict<Evidence>) -> bool {
        let (before, after) = v.detail.structure;
        far_above_floor(&m.sig)
            && v.bic_after < v.bic_before - BIC_MARGIN
            && after < before
            && v.detail.newly_near_bound.unwrap_or(0) == 0
    }
    fn adopt(&self, m: Judged, round: usize) -> Judged {
        // without a screening share the structure is re-chosen here, on every sample
        if self.screen.borrow().is_some() {
            return m;
        }
        let before = (m.fit.spec.law, m.fit.spec.springs);
        let fit = best_law(
            self.prob,
            None,
            m.fit,
            &self.laws.allowed,
            &format!("round {round}"),
            &mut self.rows.borrow_mut(),
        );
        if (fit.spec.law, fit.spec.springs) == before {
            Judged { fit, sig: m.sig }
        } else {
            self.judged(self.prob, fit)
        }
    }
    fn moved_to(&self, m: &Judged) {
        refresh_screen(&mut self.screen.borrow_mut(), &m.fit);
    }
    fn combination(&self, m: &Judged, stage: &'static str) -> Option<(CombinationAttempt, Option<Judged>)> {
        let screen = self.screen.borrow();
        // the combination's fits stop at their share of the time left, and the search goes on
        let share = self.prob.sim.deadline().map(|end| {
            let now = std::time::Instant::now();
            now + end.saturating_duration_since(now).mul_f64(COMBINATION_SHARE)
        });
        let (attempt, accepted) = self.prob.sim.within(share, || {
            try_combination(
                self.prob,
                &screen,
                &m.fit,
                &m.sig,
                stage,
                &self.laws.on_bank((m.fit.spec.law, m.fit.spec.springs)),
                &mut self.refitted.borrow_mut(),
            )
        })?;
        Some((attempt, accepted.map(|(fit, sig)| Judged { fit, sig })))
    }
    fn removal_delta_bic(&self, m: &Judged, e: Effect) -> f64 {
        removal_cost(&m.fit, self.prob.n_groups, e)
    }
    fn without(&self, m: &Judged, e: Effect) -> Option<Judged> {
        let (spec, p) = spec_without(&m.fit, self.prob.n_groups, &[e]);
        let fit = levenberg_marquardt(self.prob, spec, p, SCREEN_ITERATIONS).ok()?;
        Some(self.judged(self.prob, fit))
    }
    fn polish(&self, m: Judged) -> Option<Judged> {
        let fit = levenberg_marquardt(self.prob, m.fit.spec, m.fit.p, MAX_ITERATIONS).ok()?;
        Some(self.judged(self.prob, fit))
    }
    fn visible(&self, m: &Judged, e: Effect) -> bool {
        visibility(self.prob, &m.fit, m.sig.noise_floor, e).is_none_or(|v| v > 1.0)
    }
    fn absence_shows(&self, with: &Judged, without: &Judged) -> bool {
        absence_shows(with.sig.rmse, without.sig.rmse, with.sig.noise_floor)
    }
    fn note_absence_shown(&self, m: &Judged, e: Effect) {
        self.absence_shown.borrow_mut().push((m.fit.spec.effects.clone(), m.fit.bic().to_bits(), e));
    }
    fn absence_shown(&self, m: &Judged, e: Effect) -> bool {
        let bic = m.fit.bic().to_bits();
        self.absence_shown.borrow().iter().any(|(effects, b, x)| *x == e && *b == bic && *effects == m.fit.spec.effects)
    }
    fn lighter_hidden(&self, m: &Judged, e: Effect) -> bool {
        e == Effect::Gravity && gravity_beyond_a_load(self.prob, &m.fit).is_some_and(|moved| moved < m.sig.noise_floor)
    }
    fn defined_over(&self, e: Effect) -> Option<Effect> {
        e.defined_over()
    }
    fn swap(&self, m: &Judged, out: Effect, c: &Ranked<Effect>) -> Option<(Judged, Verdict<Evidence>)> {
        let refit = self.screened_refit(m, &[out], &[c], true)?;
        // a swap changes the model as a combination does: the bound rule applies
        let v =
            self.with_screen(m, |_, current, sig| combination_verdict(self.prob, current, sig, &refit.fit, &refit.sig));
        Some((refit, v))
    }
    fn lighter(&self, m: &Judged, e: Effect) -> Option<(Effect, Judged)> {
        let lighter = e.lighter_form()?;
        let current = &m.fit;
        if current.spec.effects.contains(&lighter) {
            return None;
        }
        let (mut spec, p) = spec_without(current, self.prob.n_groups, &[e]);
        spec.effects.push(lighter);
        // the constant part of what the heavier effect did: gravity's torque at angle 0 is ∓ m g d sin φ,
        // asymmetric friction's Coulomb asymmetry a is a load of ∓ a; both signs are tried, and none
        let offset = current.spec.offset_of(e, self.prob.n_groups)?;
        let guess = if e == Effect::Gravity { current.p[offset + 1] } else { current.p[offset] };
        let starts = [guess, -guess, 0.0].map(|g| p.iter().copied().chain([g]).collect()).to_vec();
        let fit = fit_from_best(self.prob, spec, starts, SCREEN_ITERATIONS).ok()?;
        Some((lighter, self.judged(self.prob, fit)))
    }
}

/// `model` without the effects no sample shows (`stepwise::drop_below_noise`), each removal on the
/// path and in the record; the model as it is past the budget or without effects.
fn drop_unseen(
    prob: &Problem,
    laws: &LawChoice,
    model: Judged,
    budget: &Budget,
    path: &mut Vec<Judged>,
    record: &mut Record<Effect, Signatures, Evidence>,
) -> (Fit, Signatures) {
    if model.fit.spec.effects.is_empty() || budget.spent() {
        return (model.fit, model.sig);
    }
    let rig = DeviceRig {
        prob,
        laws,
        screen: std::cell::RefCell::new(None),
        rows: std::cell::RefCell::new(Vec::new()),
        refitted: std::cell::RefCell::new(Vec::new()),
        absence_shown: std::cell::RefCell::new(Vec::new()),
        velocity_grid: false,
    };
    let (model, pruned) = super::stepwise::drop_below_noise(&rig, model, budget);
    if !pruned.is_empty() {
        path.push(model.clone());
    }
    record.pruned.extend(pruned);
    (model.fit, model.sig)
}

/// `first`: the baseline under the first structure the laws allow, where the caller fitted it
/// already (`calibrate`'s choice of the motor's band), timed by `budget`.
pub fn calibrate(prob: &mut Problem, laws: &LawChoice, budget: &Budget, first: Option<Fit>) -> Result<Outcome, String> {
    let mut rows = Vec::new();
    let t = std::time::Instant::now();
    let estimated_speeds = prob.initial_speeds();
    // timed: on long records the baseline is the longest fit, and the budget's checks after it
    // (whether a backlash scan, a fold, still fits) must know what a fit costs here
    let first = match first {
        Some(f) => f,
        None => budget.timed(|| baseline(prob, laws.allowed[0], budget.end()))?,
    };
    debug(format_args!("baseline {:?}: {:?}, {} iterations", laws.allowed[0], t.elapsed(), first.iterations));
    // With a model to report, the budget is a hard end: a fit in progress when it runs out stops
    // at its best so far. Only this first fit's start may run past it, to the backstop of
    // `hard_deadline`: the law choice and the initial speeds after it took fresh rig 492 (5 kHz,
    // three 29 s runs with gaps) from 40 s to 177 s, past its 120 s budget to the backstop.
    if let Some(end) = budget.end() {
        prob.sim.tighten_deadline(end);
    }
    let share = screening_share_fits(prob).then(|| prob.truncated(SCREEN_SHARE));
    let chosen = best_law(prob, share.as_ref(), first, &laws.allowed, "baseline", &mut rows);
    debug(format_args!("law choice: {:?}, {} simulations", t.elapsed(), sims(prob)));
    let resolved = resolve_initial_speeds(prob, chosen);
    let baseline = fit_initial_speeds(prob, resolved);
    debug(format_args!("initial speeds: {:?}, {} simulations", t.elapsed(), sims(prob)));
    let baseline_signatures = signatures(prob, &baseline);
    let rig = DeviceRig {
        prob,
        laws,
        // candidates are screened on the start of every run (cheaper), the winner is judged on all
        screen: std::cell::RefCell::new(screening_problem(prob, &baseline)),
        rows: std::cell::RefCell::new(rows),
        refitted: std::cell::RefCell::new(Vec::new()),
        absence_shown: std::cell::RefCell::new(Vec::new()),
        velocity_grid: false,
    };
    let start = Judged { fit: baseline.clone(), sig: baseline_signatures.clone() };
    let super::stepwise::Search { model, mut path, mut record } = super::stepwise::search(&rig, start, budget);
    let mut rows = rig.rows.into_inner();
    debug(format_args!("searched: {:?}, {} simulations", t.elapsed(), sims(prob)));
    let Judged { fit: mut current, mut sig } = model;
    // The final model decides every run's start again, from the estimated speeds: the baseline,
    // missing an effect (gravity, say), may have preferred a resting start for a run that does
    // start moving (a segment after a gap always does).
    // (Without effects the final model is the baseline's, whose choice stands.)
    // (Each step below is a refit or two: past the budget they are left out, the search's model stands.)
    let before_restarts = current.bic();
    let zeroed = !budget.spent()
        && !current.spec.effects.is_empty()
        && prob.inputs.iter().zip(&estimated_speeds).any(|(i, &v)| v != 0.0 && i.initial_link_speed == 0.0);
    if zeroed {
        current = budget.timed(|| restart_moving_runs(prob, current, &estimated_speeds));
    }
    if !budget.spent() {
        let before = current.sse;
        current = budget.timed(|| resolve_initial_speeds(prob, current));
        if current.sse != before || zeroed {
            sig = signatures(prob, &current);
        }
    }
    if !budget.spent() && !current.spec.effects.is_empty() {
        let before = current.sse;
        current = budget.timed(|| fit_initial_speeds(prob, current));
        if current.sse != before {
            sig = signatures(prob, &current);
        }
    }
    debug(format_args!("initial speeds again: {:?}, {} simulations", t.elapsed(), sims(prob)));
    // The search judged every candidate from the starts the baseline chose, and a start chosen
    // without friction can hold a sticking link in motion: where the final effects' starts lowered
    // the BIC by the margin and structure is left, the search runs once more from there (fresh rig
    // 655: a segment after a gap started at -0.50 rad/s where the link sticks; from that start the
    // truth's own parameters fit at 81x the floor, and the Stribeck excess beside the Coulomb
    // friction was never found; from the final model's starts its refit finds it).
    if current.bic() < before_restarts - BIC_MARGIN && !sig.white() && !budget.spent() {
        let rig = DeviceRig {
            prob,
            laws,
            screen: std::cell::RefCell::new(screening_problem(prob, &current)),
            rows: std::cell::RefCell::new(std::mem::take(&mut rows)),
            refitted: std::cell::RefCell::new(Vec::new()),
            absence_shown: std::cell::RefCell::new(Vec::new()),
            velocity_grid: true,
        };
        let why = format!(
            "the first search judged every candidate from the segments' starts the baseline chose; fitted again \
             with its effects, they lowered the BIC from {before_restarts:.0} to {:.0} with structure left, so the \
             search ran once more from there",
            current.bic()
        );
        let again = super::stepwise::search(&rig, Judged { fit: current, sig }, budget);
        rows = rig.rows.into_inner();
        debug(format_args!("searched again from the final starts: {:?}, {} simulations", t.elapsed(), sims(prob)));
        record.append_again(again.record, why);
        path.extend(again.path.into_iter().skip(1));
        (current, sig) = (again.model.fit, again.model.sig);
    }
    // An effect that stood in for a start the baseline chose wrong can be left at nothing once the
    // final effects chose the starts again (campaign rig 162: a gravity of 0.17 N.m through the
    // search, 0.008 N.m after the segment behind a 0.23 s gap started moving): it goes as in the search.
    (current, sig) = drop_unseen(prob, laws, Judged { fit: current, sig }, budget, &mut path, &mut record);
    if !budget.spent() {
        if let Some((fit, pruned)) = budget.timed(|| maxwell_as_damping(prob, &current)) {
            sig = signatures(prob, &fit);
            path.push(Judged { fit: fit.clone(), sig: sig.clone() });
            record.pruned.push(pruned);
            current = fit;
        }
    }
    // Then the structure is re-chosen with the final effects and starts: an effect found by a combination pass
    // (gravity at the baseline, say) never passed through a round's re-choice, and a law chosen
    // while an effect was missing may only have been standing in for it.
    // (two starts for each other structure). Where the budget affords no more, the damping laws under
    // the current spring bank alone: the law is what a friction found late stood in for (fresh rig 647:
    // Coulomb friction found, the hysteretic law kept from before it, C +84 % at every temperature, with
    // 41 s of its 120 s left and four structures to fit).
    let mut law_reason = laws.reason.clone();
    if !current.spec.effects.is_empty() && laws.allowed.len() > 1 {
        let before = (current.spec.law, current.spec.springs);
        match final_structures(laws, before, |fits| budget.affords(fits)) {
            None => law_reason
                .push_str("; not chosen again with the final effects: the time budget (--search-budget) held no more"),
            Some(structures) => {
                if structures.len() < laws.allowed.len() {
                    law_reason.push_str(
                        "; with the final effects only the damping laws under the chosen spring bank were refitted: \
                         the time budget (--search-budget) held no more",
                    );
                }
                current = budget.timed(|| best_law(prob, None, current, &structures, "final effects", &mut rows));
                if (current.spec.law, current.spec.springs) != before {
                    sig = signatures(prob, &current);
                    // another structure moves every parameter: an effect it leaves at nothing goes (CI
                    // rig 11: the spring bank scaled with the PCL took the friction to the truth's
                    // levels and a spurious backlash to zero width, which stayed in the set)
                    (current, sig) =
                        drop_unseen(prob, laws, Judged { fit: current, sig }, budget, &mut path, &mut record);
                }
            }
        }
    }
    if !budget.spent() {
        let before = current.sse;
        current = budget.timed(|| fit_moving_starts(prob, current));
        if current.sse != before {
            sig = signatures(prob, &current);
        }
    }
    let mut width_scan = None;
    if !budget.spent() {
        (current, width_scan) = scan_backlash_width(prob, current, budget);
        if width_scan.is_some() {
            sig = signatures(prob, &current);
        }
    }
    let (current, sig, mut backlash_laws) =
        if budget.spent() { (current, sig, None) } else { budget.timed(|| choose_backlash_law(prob, current, sig)) };
    if let Some(b) = backlash_laws.as_mut() {
        b.width_scan = width_scan;
    }
    let unexplained = !sig.white();
    Ok(Outcome {
        record,
        baseline,
        baseline_signatures,
        final_fit: current,
        final_signatures: sig,
        path: path.into_iter().map(|j| (j.fit, j.sig)).collect(),
        unexplained,
        laws: rows,
        law_reason,
        backlash_laws,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The noise hides a share that leaves a right model explained: fresh rig 1486's asymmetric
    /// friction (its refit without took the rms from 1.033 to 1.305 times the floor) shows; rig
    /// 1481's thermal lag (1.036 to 1.089) and rig 1479's spurious gravity, beside a model far from
    /// the floor (3.685 to 3.710), do not. The line sits at a share of √(1.2² − 1) of the floor.
    #[test]
    fn an_absence_shows_where_a_right_model_without_it_would_not_be_explained() {
        assert!(absence_shows(1.033, 1.305, 1.0));
        assert!(!absence_shows(1.036, 1.089, 1.0));
        assert!(!absence_shows(3.685, 3.710, 1.0));
        let line = (EXPLAINED_LINE.powi(2) - 1.0).sqrt();
        let floor = 2.5e-4;
        assert!(absence_shows(0.0, 1.01 * line * floor, floor) && !absence_shows(0.0, 0.99 * line * floor, floor));
    }

    /// A budget that holds the laws but not every spring bank still re-chooses the law under the
    /// current bank; one that holds neither re-chooses nothing.
    #[test]
    fn the_final_structures_narrow_to_the_current_banks_laws_before_none() {
        use DampingLaw::{Hysteretic, Viscous};
        use SpringBank::{Nominal, Scaled};
        let allowed = vec![(Viscous, Scaled), (Viscous, Nominal), (Hysteretic, Scaled), (Hysteretic, Nominal)];
        let laws = |allowed: Vec<Structure>| LawChoice { allowed, reason: String::new(), undecided: false };
        let four = laws(allowed.clone());
        assert_eq!(final_structures(&four, (Hysteretic, Scaled), |fits| fits <= 6.0), Some(allowed.clone()));
        let on_bank = final_structures(&four, (Hysteretic, Scaled), |fits| fits <= 2.0);
        assert_eq!(on_bank, Some(vec![(Hysteretic, Scaled), (Viscous, Scaled)]));
        let nominal = final_structures(&four, (Viscous, Nominal), |fits| fits <= 2.0);
        assert_eq!(nominal, Some(vec![(Viscous, Nominal), (Hysteretic, Nominal)]));
        assert_eq!(final_structures(&four, (Viscous, Scaled), |fits| fits < 2.0), None);
        // one structure allowed: nothing to choose
        assert_eq!(final_structures(&laws(allowed[..1].to_vec()), (Viscous, Scaled), |_| true), None);
    }

    #[test]
    fn a_candidate_is_refitted_under_every_law_on_the_current_bank_only() {
        use DampingLaw::{Hysteretic, Viscous};
        use SpringBank::{Nominal, Scaled};
        let heating = LawChoice {
            allowed: vec![(Viscous, Scaled), (Viscous, Nominal), (Hysteretic, Scaled), (Hysteretic, Nominal)],
            reason: String::new(),
            undecided: false,
        };
        assert_eq!(heating.on_bank((Hysteretic, Nominal)), vec![(Hysteretic, Nominal), (Viscous, Nominal)]);
        assert_eq!(heating.on_bank((Viscous, Scaled)), vec![(Viscous, Scaled), (Hysteretic, Scaled)]);
        // a steady thermocouple allows one bank: every structure, the current one first, as before
        let steady = LawChoice { allowed: vec![(Viscous, Scaled), (Hysteretic, Scaled)], ..heating };
        assert_eq!(steady.on_bank((Hysteretic, Scaled)), vec![(Hysteretic, Scaled), (Viscous, Scaled)]);
    }

    #[test]
    fn removing_a_stribeck_excess_zeroes_its_level_not_its_speed() {
        // one temperature group (ln K, ln C), Coulomb friction, a Stribeck excess (level, ln speed):
        // the excess is gone when its level is zero. Forcing ln v to 0 as well read a speed of 1 rad/s
        // into the removal, so its cost moved with where the speed sat while the fit (its Jacobian,
        // its SSE) stayed the same
        let n = 400;
        let jacobian = super::super::stepwise::five_smooth_columns(n);
        let spec = ModelSpec {
            effects: vec![Effect::CoulombFriction, Effect::StribeckFriction],
            law: DampingLaw::Viscous,
            springs: SpringBank::Scaled,
            elasto_backlash: false,
        };
        let fit_with_speed = |speed: f64| Fit {
            spec: spec.clone(),
            p: vec![3.5, -1.0, 0.46, 0.01, speed.ln()],
            outputs: vec![],
            residual: vec![],
            sse: 1e-4,
            n,
            jacobian: jacobian.clone(),
            covariance: DMatrix::zeros(0, 0),
            iterations: 0,
        };
        let (slow, fast) = (fit_with_speed(4.05e-3), fit_with_speed(4.05));
        assert_eq!(level_columns(&slow, 1, Effect::StribeckFriction), vec![3]);
        let (a, b) =
            (removal_cost(&slow, 1, Effect::StribeckFriction), removal_cost(&fast, 1, Effect::StribeckFriction));
        assert!(a.is_finite() && (a - b).abs() <= 1e-9 * a.abs().max(1.0), "{a} against {b}");
        // and Coulomb friction's removal reads its level alone too
        assert_eq!(level_columns(&slow, 1, Effect::CoulombFriction), vec![2]);
    }

    #[test]
    fn candidates_off_leave_the_current_parameters_and_zero_levels_with_their_scales() {
        let ranked = |effect: Effect, start: Vec<f64>| Ranked {
            effect,
            score: 0.5,
            predicted_delta_bic: -100.0,
            start,
            moved: Vec::new(),
            evidence: String::new(),
        };
        let (stribeck, gravity) =
            (ranked(Effect::StribeckFriction, vec![0.05, 0.3f64.ln()]), ranked(Effect::Gravity, vec![0.2, -0.1]));
        let current = [3.5, -1.0, 0.46];
        assert_eq!(off(&current, &[&stribeck, &gravity]), vec![3.5, -1.0, 0.46, 0.0, 0.3f64.ln(), 0.0, 0.0]);
    }

    #[test]
    fn asymmetric_friction_brings_in_the_levels_it_splits_where_the_model_lacks_them() {
        let ranked = |effect: Effect| Ranked {
            effect,
            score: 0.5,
            predicted_delta_bic: -100.0,
            start: vec![0.01; effect.params().len()],
            moved: Vec::new(),
            evidence: String::new(),
        };
        let (asym, coulomb, gravity) =
            (ranked(Effect::AsymmetricFriction), ranked(Effect::CoulombFriction), ranked(Effect::Gravity));
        let effects = |l: Vec<Ranked<Effect>>| l.iter().map(|c| (c.effect, c.start.clone())).collect::<Vec<_>>();
        // over a model with a constant load only: both levels, from zero
        assert_eq!(
            effects(levels_lacking(&[Effect::ConstantLoad], &[&asym])),
            vec![(Effect::CoulombFriction, vec![0.0]), (Effect::LinkDamping, vec![0.0])]
        );
        // Coulomb friction in the model or in the pair is not brought twice
        assert_eq!(
            effects(levels_lacking(&[Effect::CoulombFriction], &[&asym])),
            vec![(Effect::LinkDamping, vec![0.0])]
        );
        assert_eq!(effects(levels_lacking(&[], &[&coulomb, &asym])), vec![(Effect::LinkDamping, vec![0.0])]);
        assert!(levels_lacking(&[Effect::CoulombFriction, Effect::LinkDamping], &[&asym]).is_empty());
        // an effect that splits no levels brings nothing
        assert!(levels_lacking(&[], &[&gravity, &coulomb]).is_empty());
    }
}
