//! The loop: fit the nominal model, diagnose, add the best-supported effect, refit everything,
//! keep it only if it earns its place, repeat until nothing in the library helps.

use super::diagnose::{rank, signatures, Candidate, Signatures};
use super::fit::{
    levenberg_marquardt, regressor_columns, DampingLaw, Effect, EquationError, Fit, ModelSpec, NormalEquations,
    Problem, SpringBank, EQUATION_ERROR_EFFECTS,
};

/// An effect is kept only when the refit lowers the BIC by more than this: "very strong" evidence
/// on the Kass & Raftery (1995) scale (ΔBIC > 10).
pub const BIC_MARGIN: f64 = 10.0;
/// Fraction of the residual's low-frequency structure (over white noise) an effect must remove.
pub const STRUCTURE_DROP: f64 = 1.0 / 3.0;
/// Refits tried per round, best-ranked first.
pub const TRIES_PER_ROUND: usize = 3;
/// The one-at-a-time rounds stop at this many effects as reported (asymmetric friction with the
/// Coulomb and viscous levels under it counts once).
pub const MAX_EFFECTS: usize = 5;
pub const MAX_ITERATIONS: usize = 25;
/// Levenberg–Marquardt iterations a shortlisted candidate gets before the comparison; the
/// winner then runs to convergence (speed: most of a search is spent on losers).
pub const SCREEN_ITERATIONS: usize = 4;

/// The equation error's best subsets refitted through the FMU when combinations are tried.
pub const SUBSETS_REFITTED: usize = 3;

/// Times the equation error's combination is tried after the one-at-a-time rounds (each accepted
/// one is followed by rounds again).
pub const COMBINATION_PASSES: usize = 2;

/// Candidates (by score, each predicting a BIC gain) refitted in pairs when no single one earns
/// its place: 4 give 6 pairs.
pub const PAIR_POOL: usize = 4;

/// A candidate is refitted only if its linearised score is at least this share of the best one's.
pub const SHORTLIST_SHARE: f64 = 0.25;

/// The backward check skips the refit of an effect whose linearised removal costs more than this
/// many BIC margins.
pub const PRUNE_SKIP: f64 = 10.0;

/// An effect earns its place if BIC falls by more than `BIC_MARGIN` and the residual loses at least
/// `STRUCTURE_DROP` of its low-frequency excess over white noise (BIC alone, with N = every
/// sample, over-rewards small effects fitting correlated leftovers).
fn earns_its_place(current: &Fit, sig: &Signatures, refit: &Fit, refit_sig: &Signatures) -> bool {
    let excess = |x: f64| (x - 1.0).max(0.0);
    refit.bic() < current.bic() - BIC_MARGIN
        && excess(refit_sig.structure_ratio) <= (1.0 - STRUCTURE_DROP) * excess(sig.structure_ratio)
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

/// Whether some temperature group's stiffness or damping sits on its bound.
pub fn at_bound(prob: &Problem, fit: &Fit) -> bool {
    (0..prob.n_groups).any(|g| prob.transmission_at_bound(g, &fit.p))
}

/// Predicted BIC change of removing effect `e` from `fit` (the others re-adjusted, linearised).
fn removal_delta_bic(fit: &Fit, e: Effect, n_groups: usize) -> f64 {
    let Some((o, _)) = fit.spec.offsets(n_groups).into_iter().find(|(_, x)| *x == e) else { return f64::NEG_INFINITY };
    let k = e.params().len();
    let inv = super::fit::spd_inverse(&(fit.jacobian.transpose() * &fit.jacobian));
    let block = inv.view((o, o), (k, k)).into_owned();
    let theta = nalgebra::DVector::from_column_slice(&fit.p[o..o + k]);
    let delta_sse = (theta.transpose() * super::fit::spd_inverse(&block) * &theta)[(0, 0)].max(0.0);
    let n = fit.n as f64;
    n * ((fit.sse + delta_sse) / fit.sse.max(1e-300)).ln() - k as f64 * n.ln()
}

/// One round of diagnosis and what came of it.
#[derive(Clone, Debug)]
pub struct Round {
    pub signatures: Signatures,
    pub candidates: Vec<Candidate>,
    /// (effect, BIC before, BIC after, structure ratio before, after, kept)
    pub attempts: Vec<(Effect, f64, f64, f64, f64, bool)>,
}

/// The time the effect search may take. Checked between refits: a refit under way finishes.
pub struct Budget {
    pub start: std::time::Instant,
    pub seconds: f64,
    /// Set when the search stopped because the budget ran out: what it was about to do.
    pub exhausted: std::cell::Cell<Option<&'static str>>,
}

impl Budget {
    pub fn seconds(seconds: f64) -> Budget {
        Budget { start: std::time::Instant::now(), seconds, exhausted: std::cell::Cell::new(None) }
    }
    /// Whether the search may go on to `next`; records the first refusal.
    pub fn allows(&self, next: &'static str) -> bool {
        if self.exhausted.get().is_some() {
            return false;
        }
        if self.start.elapsed().as_secs_f64() > self.seconds {
            self.exhausted.set(Some(next));
            return false;
        }
        true
    }
}

/// A combination of effects proposed by the equation error's best subset and refitted at once.
#[derive(Clone, Debug)]
pub struct CombinationAttempt {
    /// When it was tried: "baseline" (before the one-at-a-time rounds) or "after the rounds".
    pub stage: &'static str,
    pub effects: Vec<Effect>,
    /// (BIC, structure ratio) of the model it was compared with, and of the refit.
    pub before: (f64, f64),
    pub after: (f64, f64),
    pub kept: bool,
}

pub struct Outcome {
    /// Set when the search budget ran out: (seconds allowed, what was skipped).
    pub budget_exhausted: Option<(f64, &'static str)>,
    pub combinations: Vec<CombinationAttempt>,
    pub baseline: Fit,
    pub baseline_signatures: Signatures,
    pub final_fit: Fit,
    pub final_signatures: Signatures,
    pub rounds: Vec<Round>,
    /// Effects removed again by the backward check: (effect, BIC with it, BIC without).
    pub pruned: Vec<(Effect, f64, f64)>,
    pub unexplained: bool,
    /// Damping laws compared (baseline and after each added effect).
    pub laws: Vec<LawRow>,
    pub law_reason: String,
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

/// Sum of squared residuals at `p` (infinite when the FMU cannot simulate it).
fn cost(prob: &Problem, spec: &ModelSpec, p: &[f64]) -> f64 {
    prob.outputs(spec, p).map(|o| prob.residual(&o).iter().map(|x| x * x).sum::<f64>()).unwrap_or(f64::INFINITY)
}

/// Levenberg–Marquardt from the cheapest of several starts (each simulated once).
fn fit_from_best(prob: &Problem, spec: ModelSpec, starts: Vec<Vec<f64>>, max_iter: usize) -> Result<Fit, String> {
    let p0 = starts
        .into_iter()
        .map(|p| (cost(prob, &spec, &p), p))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, p)| p)
        .ok_or("no start")?;
    levenberg_marquardt(prob, spec, p0, max_iter)
}

/// The nominal model at its optimum under one damping law (issue 10, item 3): every start is
/// simulated once, and Levenberg–Marquardt runs from the best one.
pub fn baseline(prob: &Problem, (law, springs): Structure) -> Result<Fit, String> {
    let starts = baseline_starts(prob, law).into_iter().map(|s| s.1).collect();
    fit_from_best(prob, ModelSpec { effects: vec![], law, springs }, starts, MAX_ITERATIONS)
}

/// The combinations of linear effects ([`EQUATION_ERROR_EFFECTS`]) the equation error supports,
/// with the transmission of every temperature group fitted beside them (so neither absorbs the
/// other, and no bound pins it): of every subset (asymmetric friction only with Coulomb
/// friction), the lowest BIC on the regression's independent rows among those in which each
/// effect's removal costs more than `BIC_MARGIN`: the best `count` of them, best first. The
/// regression is formed once; every subset is solved from its normal equations.
pub fn equation_error_subsets(prob: &Problem, law: DampingLaw, count: usize) -> Vec<Vec<Effect>> {
    let all = EQUATION_ERROR_EFFECTS;
    let Some(normal) = prob.normal_equations(law, &all, 0.0) else { return Vec::new() };
    // with backlash: the same regression at each width of the grid (the best width per subset)
    let with_play: Vec<NormalEquations> =
        prob.backlash_width_grid().into_iter().filter_map(|w| prob.normal_equations(law, &all, w)).collect();
    let n_t = 2 * prob.n_groups;
    let mut offsets = Vec::with_capacity(all.len());
    let mut next = n_t;
    for e in all {
        offsets.push(next);
        next += regressor_columns(e);
    }
    let bit = |e: Effect| 1u32 << all.iter().position(|&x| x == e).expect("in the list");
    let valid = |mask: u32| mask & bit(Effect::AsymmetricFriction) == 0 || mask & bit(Effect::CoulombFriction) != 0;
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
            // a Stribeck excess is defined over a Coulomb level; a model an earlier pass refitted
            // from the same equation error is not refitted again (only the current transmission's
            // start would differ)
            let stribeck_alone =
                effects.contains(&Effect::StribeckFriction) && !effects.contains(&Effect::CoulombFriction);
            let key = (structure, effects);
            if stribeck_alone || refitted.contains(&key) {
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
    // (the current transmission only when it is off its bounds: a rigid or limp link is no start,
    // and a stiff one with friction is slow to simulate)
    let feasible = !at_bound(prob, current);
    let (sprob, scurrent, ssig) = screened(screen, prob, current, sig);
    let t = std::time::Instant::now();
    // Each structure's best subset from every start (a transmission that absorbed an effect, or
    // sits at a bound, is a valley of its own), the others from their cheapest start.
    let mut fits: Vec<Fit> = Vec::new();
    let mut first_of: Vec<Structure> = Vec::new();
    for ((law, springs), subset, ee) in &proposals {
        let mut effects = kept_effects.clone();
        effects.extend_from_slice(subset);
        let spec = ModelSpec { effects, law: *law, springs: *springs };
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
    let effects = screened.spec.effects.clone();
    let screened_sig = signatures(sprob, &screened);
    let mut attempt = CombinationAttempt {
        stage,
        effects,
        before: (scurrent.bic(), ssig.structure_ratio),
        after: (screened.bic(), screened_sig.structure_ratio),
        kept: earns_its_place(scurrent, ssig, &screened, &screened_sig),
    };
    debug(format_args!("combination {:?} screened in {:?}: kept {}", attempt.effects, t.elapsed(), attempt.kept));
    if !attempt.kept {
        return Some((attempt, None));
    }
    let done = if screen.is_some() {
        levenberg_marquardt(prob, screened.spec.clone(), screened.p.clone(), MAX_ITERATIONS).ok()?
    } else {
        screened
    };
    let s = signatures(prob, &done);
    attempt.before = (current.bic(), sig.structure_ratio);
    attempt.after = (done.bic(), s.structure_ratio);
    attempt.kept = earns_its_place(current, sig, &done, &s);
    let accepted = attempt.kept.then_some((done, s));
    Some((attempt, accepted))
}

/// Starting points for refitting `current` with the candidates' effects added: the current
/// transmission and the closed-form one (the transmission fitted without an effect may have
/// absorbed it: friction mimicked by a softer, more damped link; gravity by a rigid one), each with
/// the linearised effect values and with the effects' typical sizes (a linearisation at a rigid or
/// bounded fit can be absurd); and the equation error with the effects' torques as regressors
/// (transmission and effects estimated together, so neither absorbs the other).
fn candidate_starts(prob: &Problem, current: &Fit, added: &[&Candidate], law: DampingLaw) -> Vec<Vec<f64>> {
    let n_t = 2 * prob.n_groups;
    let closed = prob.closed_form_start(law);
    let linearised: Vec<f64> = added.iter().flat_map(|c| c.start.iter().copied()).collect();
    let typical: Vec<f64> = added.iter().flat_map(|c| c.effect.params().iter().map(|p| p.1)).collect();
    let mut starts = Vec::new();
    for transmission in [&current.p[..n_t], &closed[..]] {
        for effect in [&linearised, &typical] {
            let mut q = transmission.to_vec();
            q.extend_from_slice(&current.p[n_t..]);
            q.extend_from_slice(effect);
            starts.push(q);
        }
    }
    let effects: Vec<Effect> = added.iter().map(|c| c.effect).collect();
    if let Some(e) = prob.equation_error(law, &effects).filter(|e| e.repaired.is_empty()) {
        let mut q = e.p[..n_t].to_vec();
        q.extend_from_slice(&current.p[n_t..]);
        q.extend_from_slice(&e.p[n_t..]);
        starts.push(q);
    }
    starts
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
        let spec = ModelSpec { effects: best.spec.effects.clone(), law, springs };
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

/// One comparison of damping laws.
#[derive(Clone, Debug)]
pub struct LawRow {
    pub stage: String,
    pub structure: Structure,
    pub rmse: f64,
    pub bic: f64,
}

/// Runs started moving (`calibrate::initial_speed` saw the link moving at its first sample) are
/// fitted again at rest with `fit`'s structure; a run keeps the moving start only when it lowers
/// that run's BIC by more than `BIC_MARGIN` (one more number per run). A link that starts at rest
/// and catches up with the motor within a millisecond looks moving over the estimator's window,
/// so the model decides: once with the baseline, and again with the final model for the runs
/// still moving. Returns the fit refitted with the chosen starts.
pub fn resolve_initial_speeds(prob: &mut Problem, moving: Fit) -> Fit {
    let speeds: Vec<f64> = prob.inputs.iter().map(|i| i.initial_link_speed).collect();
    if speeds.iter().all(|&v| v == 0.0) {
        return moving;
    }
    prob.inputs.iter_mut().for_each(|i| i.initial_link_speed = 0.0);
    let Ok(resting) = levenberg_marquardt(prob, moving.spec.clone(), moving.p.clone(), MAX_ITERATIONS) else {
        prob.inputs.iter_mut().zip(&speeds).for_each(|(i, v)| i.initial_link_speed = *v);
        return moving;
    };
    let lengths = prob.lengths();
    let per_run = |f: &Fit| -> Vec<f64> {
        let mut offset = 0;
        lengths
            .iter()
            .map(|&n| {
                let s = f.residual[offset..offset + n].iter().map(|e| e * e).sum();
                offset += n;
                s
            })
            .collect()
    };
    let (sm, sr) = (per_run(&moving), per_run(&resting));
    let mut kept = 0;
    for (r, inp) in prob.inputs.iter_mut().enumerate() {
        let n = lengths[r] as f64;
        if speeds[r] != 0.0 && n * (sr[r] / sm[r]).ln() > n.ln() + BIC_MARGIN {
            inp.initial_link_speed = speeds[r];
            kept += 1;
        }
    }
    if kept == 0 {
        return resting;
    }
    if kept == speeds.iter().filter(|&&v| v != 0.0).count() {
        return moving;
    }
    let start = if resting.sse < moving.sse { resting.p.clone() } else { moving.p.clone() };
    levenberg_marquardt(prob, moving.spec.clone(), start, MAX_ITERATIONS).unwrap_or(moving)
}

/// `THERMOVIA_DEBUG=1`: where the loop's time goes, on stderr.
pub fn debug(what: std::fmt::Arguments) {
    if std::env::var_os("THERMOVIA_DEBUG").is_some() {
        eprintln!("{what}");
    }
}

/// Simulations run so far (for `debug`).
fn sims(prob: &Problem) -> usize {
    prob.sim.simulations.load(std::sync::atomic::Ordering::Relaxed)
}

pub fn calibrate(prob: &mut Problem, laws: &LawChoice, budget: &Budget) -> Result<Outcome, String> {
    let mut rows = Vec::new();
    let t = std::time::Instant::now();
    let first = baseline(prob, laws.allowed[0])?;
    debug(format_args!("baseline {:?}: {:?}, {} iterations", laws.allowed[0], t.elapsed(), first.iterations));
    let share = screening_share_fits(prob).then(|| prob.truncated(SCREEN_SHARE));
    let chosen = best_law(prob, share.as_ref(), first, &laws.allowed, "baseline", &mut rows);
    debug(format_args!("law choice: {:?}, {} simulations", t.elapsed(), sims(prob)));
    let baseline = resolve_initial_speeds(prob, chosen);
    debug(format_args!("initial speeds: {:?}, {} simulations", t.elapsed(), sims(prob)));
    let baseline_signatures = signatures(prob, &baseline);
    // candidates are screened on the start of every run (cheaper), the winner is judged on all
    let mut screen = screening_problem(prob, &baseline);
    let mut current = baseline.clone();
    let mut sig = baseline_signatures.clone();
    let mut rounds = Vec::new();
    // The equation error's best subsets are refitted at once first (issue 18): several effects
    // together, where one at a time each would be judged against a baseline that absorbed the
    // others (and a baseline at a bound is infeasible: linearised rankings around it are blind, a
    // rigid link does not feel a small probe). A greedy first step can also take a wrong effect
    // that mimics two (gravity at an offset for asymmetric friction) and never leave it.
    let mut combinations = Vec::new();
    let mut refitted = Vec::new();
    if !sig.white() && budget.allows("the equation error's combination at the baseline") {
        if let Some((attempt, accepted)) =
            try_combination(prob, &screen, &current, &sig, "baseline", &laws.allowed, &mut refitted)
        {
            combinations.push(attempt);
            if let Some((f, s)) = accepted {
                current = f;
                sig = s;
                refresh_screen(&mut screen, &current);
            }
        }
    }
    // until the residual is white at the noise floor, or nothing in the library earns its place
    // The baseline is always diagnosed (the ranking and its evidence are reported even for a
    // white residual); refits happen only while structure remains.
    // One-at-a-time rounds, then the equation error's combination with what they found (a partial
    // effect found first can hide the rest); rounds again after an accepted combination.
    let mut passes = 0;
    loop {
        while current.spec.reported_effects().len() < MAX_EFFECTS
            && (rounds.is_empty() || !sig.white())
            && budget.allows("a round of one-at-a-time refits")
        {
            let t = std::time::Instant::now();
            // ranked on the screening share too (the linearised projections need no more)
            let (rprob, rcurrent, rsig) = screened(&screen, prob, &current, &sig);
            let candidates = rank(rprob, rcurrent, rsig);
            debug(format_args!("rank took {:?}", t.elapsed()));
            let mut round = Round { signatures: rsig.clone(), candidates: candidates.clone(), attempts: vec![] };
            // The linearised ranking shortlists; the refits decide: of the shortlisted effects that
            // earn their place, the one with the lowest BIC is added.
            let mut accepted: Option<(Fit, Signatures)> = None;
            let shortlist = if sig.white() { 0 } else { TRIES_PER_ROUND };
            // refits are for candidates the linearised ranking cannot tell apart from the best: a
            // score below SHORTLIST_SHARE of the best one's is not worth a refit
            // (unless the fit sits at a bound, where the linearisation is blind: a rigid fit does not
            // feel a small gravity probe)
            let best_score = if at_bound(prob, &current) { 0.0 } else { candidates.first().map_or(0.0, |c| c.score) };
            for c in candidates
                .iter()
                .filter(|c| c.predicted_delta_bic < -BIC_MARGIN && c.score >= SHORTLIST_SHARE * best_score)
                .take(shortlist)
            {
                let mut spec = current.spec.clone();
                spec.effects.push(c.effect);
                let starts = candidate_starts(prob, &current, &[c], spec.law);
                let (sprob, scurrent, ssig) = screened(&screen, prob, &current, &sig);
                let t = std::time::Instant::now();
                let Ok(refit) = fit_from_best(sprob, spec, starts, SCREEN_ITERATIONS) else { continue };
                debug(format_args!(
                    "refit {} took {:?}, {} iterations",
                    c.effect.name(),
                    t.elapsed(),
                    refit.iterations
                ));
                let refit_sig = signatures(sprob, &refit);
                // it earns its place if BIC says so and the residual lost the structure it explained:
                // at least STRUCTURE_DROP of the low-frequency excess over white noise (BIC alone,
                // with N = every sample, over-rewards small effects fitting correlated leftovers)
                let keep = earns_its_place(scurrent, ssig, &refit, &refit_sig);
                round.attempts.push((
                    c.effect,
                    scurrent.bic(),
                    refit.bic(),
                    ssig.structure_ratio,
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
            // No single effect earned its place while structure remains: a partial effect is
            // judged against a model that lacks its partner (friction with backlash), so the
            // BIC-improving candidates are refitted in pairs.
            let mut pair_index = None;
            // (not from a fit at a bound, whose linearised ranking is blind)
            if accepted.is_none() && shortlist > 0 && !at_bound(prob, &current) && budget.allows("pairs of candidates")
            {
                let (sprob, scurrent, ssig) = screened(&screen, prob, &current, &sig);
                let pool: Vec<&Candidate> =
                    candidates.iter().filter(|c| c.predicted_delta_bic < -BIC_MARGIN).take(PAIR_POOL).collect();
                let first_pair = combinations.len();
                for (i, a) in pool.iter().enumerate() {
                    for b in &pool[i + 1..] {
                        let mut spec = current.spec.clone();
                        spec.effects.extend([a.effect, b.effect]);
                        let starts = candidate_starts(prob, &current, &[a, b], spec.law);
                        let Ok(refit) = fit_from_best(sprob, spec, starts, SCREEN_ITERATIONS) else { continue };
                        let refit_sig = signatures(sprob, &refit);
                        let keep = earns_its_place(scurrent, ssig, &refit, &refit_sig);
                        debug(format_args!("pair {} + {}: kept {keep}", a.effect.name(), b.effect.name()));
                        combinations.push(CombinationAttempt {
                            stage: "pair after a round",
                            effects: vec![a.effect, b.effect],
                            before: (scurrent.bic(), ssig.structure_ratio),
                            after: (refit.bic(), refit_sig.structure_ratio),
                            kept: keep,
                        });
                        if keep && accepted.as_ref().is_none_or(|x: &(Fit, Signatures)| refit.bic() < x.0.bic()) {
                            accepted = Some((refit, refit_sig));
                            pair_index = Some(combinations.len() - 1);
                        }
                    }
                }
                // only this round's winner stays marked kept (earlier rounds' records are final)
                for (k, c) in combinations.iter_mut().enumerate().skip(first_pair) {
                    if Some(k) != pair_index {
                        c.kept = false;
                    }
                }
            }
            debug(format_args!("round screened: {:?}, {} simulations", t.elapsed(), sims(prob)));
            // the winner runs to convergence on every sample, and must earn its place there too
            if let Some((f, fs)) = accepted.take() {
                // an effect can change which damping law the data favour (friction read as frequency-
                // dependent loss before it was in): re-chosen on the screening share with it, so only
                // the chosen structure is fitted on every sample
                let f = match &screen {
                    Some((sp, _, _)) => {
                        let stage = format!("round {} (screening share)", rounds.len() + 1);
                        best_law(sp, None, f, &laws.allowed, &stage, &mut rows)
                    }
                    None => f,
                };
                if screen.is_none() && f.iterations < SCREEN_ITERATIONS {
                    accepted = Some((f, fs));
                } else if let Ok(done) = levenberg_marquardt(prob, f.spec.clone(), f.p.clone(), MAX_ITERATIONS) {
                    debug(format_args!("winner {} iterations, SSE {:.6e} → {:.6e}", done.iterations, f.sse, done.sse));
                    let s = signatures(prob, &done);
                    if earns_its_place(&current, &sig, &done, &s) {
                        accepted = Some((done, s));
                    } else if let Some(a) = round.attempts.iter_mut().find(|a| a.5) {
                        a.5 = false;
                    } else if let Some(k) = pair_index {
                        combinations[k].kept = false;
                    }
                }
            }
            debug(format_args!("winner converged: {:?}, {} simulations", t.elapsed(), sims(prob)));
            rounds.push(round);
            match accepted {
                Some((f, s)) => {
                    // (without a screening share the structure is re-chosen here, on every sample)
                    if screen.is_none() {
                        let before = (f.spec.law, f.spec.springs);
                        current = best_law(prob, None, f, &laws.allowed, &format!("round {}", rounds.len()), &mut rows);
                        sig = if (current.spec.law, current.spec.springs) == before {
                            s
                        } else {
                            signatures(prob, &current)
                        };
                    } else {
                        current = f;
                        sig = s;
                    }
                    debug(format_args!(
                        "law re-checked: {:?}, {} simulations, {:?}",
                        t.elapsed(),
                        sims(prob),
                        current.spec.law
                    ));
                    refresh_screen(&mut screen, &current);
                }
                None => break,
            }
        }
        passes += 1;
        if sig.white()
            || passes > COMBINATION_PASSES
            || !budget.allows("the equation error's combination after the rounds")
        {
            break;
        }
        match try_combination(prob, &screen, &current, &sig, "after the rounds", &laws.allowed, &mut refitted) {
            Some((attempt, Some((f, s)))) => {
                combinations.push(attempt);
                current = f;
                sig = s;
                refresh_screen(&mut screen, &current);
            }
            Some((attempt, None)) => {
                combinations.push(attempt);
                break;
            }
            None => break,
        }
    }
    // Backward check: an effect added early may be redundant once a later one is in (a Maxwell
    // branch standing in for link damping). Drop any whose removal does not cost BIC_MARGIN.
    let mut pruned = Vec::new();
    let mut changed = current.spec.effects.len() > 1;
    while changed && budget.allows("the backward check") {
        changed = false;
        for &e in current.spec.effects.clone().iter() {
            let spec = ModelSpec {
                effects: current.spec.effects.iter().copied().filter(|&x| x != e).collect(),
                law: current.spec.law,
                springs: current.spec.springs,
            };
            let mut p = current.p[..2 * prob.n_groups].to_vec();
            for (o, x) in current.spec.offsets(prob.n_groups) {
                if x != e {
                    p.extend_from_slice(&current.p[o..o + x.params().len()]);
                }
            }
            // Linearised first: the Gauss–Newton cost of forcing the effect off while the rest
            // re-adjusts, θ_eᵀ [(JᵀJ)⁻¹]_ee⁻¹ θ_e. Far beyond the margin, the effect is plainly
            // needed, and a refit without it would only wander to a bound, where every simulation
            // is slow.
            if removal_delta_bic(&current, e, prob.n_groups) > PRUNE_SKIP * BIC_MARGIN {
                continue;
            }
            debug(format_args!("prune screen of {}: {:?}", e.name(), t.elapsed()));
            // then a screening refit: if even that cannot come within the margin, keep the effect
            let Ok(screen) = levenberg_marquardt(prob, spec.clone(), p, SCREEN_ITERATIONS) else { continue };
            if screen.bic() >= current.bic() + BIC_MARGIN {
                continue;
            }
            let Ok(refit) = levenberg_marquardt(prob, spec, screen.p, MAX_ITERATIONS) else { continue };
            if refit.bic() < current.bic() + BIC_MARGIN {
                pruned.push((e, current.bic(), refit.bic()));
                sig = signatures(prob, &refit);
                current = refit;
                changed = current.spec.effects.len() > 1;
                break;
            }
        }
    }
    debug(format_args!("pruned: {:?}, {} simulations", t.elapsed(), sims(prob)));
    if prob.inputs.iter().any(|i| i.initial_link_speed != 0.0) {
        let before = current.sse;
        current = resolve_initial_speeds(prob, current);
        if current.sse != before {
            sig = signatures(prob, &current);
        }
    }
    debug(format_args!("initial speeds again: {:?}, {} simulations", t.elapsed(), sims(prob)));
    let unexplained = !sig.white();
    Ok(Outcome {
        budget_exhausted: budget.exhausted.get().map(|what| (budget.seconds, what)),
        combinations,
        baseline,
        baseline_signatures,
        final_fit: current,
        final_signatures: sig,
        rounds,
        pruned,
        unexplained,
        laws: rows,
        law_reason: laws.reason.clone(),
    })
}
