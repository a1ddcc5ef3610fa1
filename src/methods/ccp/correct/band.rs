//! The band corrections of paper sec. band_method: keeping the number of particles that cross
//! the band interface consistent with the room in the interface and the deep.
//!
//! Let `L = C_<=-R` be the band interface and the deep of the previous markings, `gamma_in` the
//! moves into `L` and `gamma_out` the moves out of it, and `alpha_<=-R` the room (missing
//! particles) in `L` (sec. band_con). The band constraint eq. band_con asks
//! `0 <= n_in - n_out <= alpha_<=-R`. Three variants enforce it:
//!
//! - [`BandVariant::Full`]: eq. problem3 with eq. band_con and eq. band_con_update as one
//!   integer program (microlp's branch and bound). Exact, and only practical on small problems.
//! - [`BandVariant::OneWay`]: solve eq. problem3 first (`b*`); when `s_in` or `s_out` is
//!   negative, solve again with the one-way constraint eq. band_con2 or eq. band_con3, an
//!   integer program with one dense row (sec. band_con2).
//! - [`BandVariant::Paths`]: keep `b*` and push `n_move` particles along grid paths into or out
//!   of `L` (sec. push_part): alg. find, alg. edge and alg. update, as written
//!   ([`super::path_search`]).
//! - [`BandVariant::ExactPaths`] (beyond the paper): keep `b*` and solve the problem the paths
//!   solve greedily to optimality, as a min-cost flow ([`super::exact_paths`]).

use crate::grid::{Grid, Vector};
use crate::solvers::lp::{self, SideConstraint};
use crate::solvers::min_cost_flow::FlowStats;
use crate::stages::markings::{DepthLevel, Markings};
use rayon::prelude::*;
use std::time::{Duration, Instant};

use super::exact_paths::SecondStep;
use super::path_search::PathSearch;
use super::paths::{BandPath, BandScene, PathDirection};
use super::problem::CorrectionProblem;
use super::{Fallback, SolveError, Solved};

/// How the correction keeps the band's count right (sec. band_con, band_con2, push_part).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BandVariant {
    Full,
    OneWay,
    Paths,
    ExactPaths,
}

impl BandVariant {
    pub const ALL: [BandVariant; 4] = [
        BandVariant::Full,
        BandVariant::OneWay,
        BandVariant::Paths,
        BandVariant::ExactPaths,
    ];

    pub fn name(self) -> &'static str {
        match self {
            BandVariant::Full => "full",
            BandVariant::OneWay => "one-way",
            BandVariant::Paths => "paths",
            BandVariant::ExactPaths => "exact-paths",
        }
    }

    /// Whether the variant solves integer programs by branch and bound (microlp), which only
    /// small problems allow.
    pub fn needs_ilp(self) -> bool {
        matches!(self, BandVariant::Full | BandVariant::OneWay)
    }
}

/// The band as the correction sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BandContext {
    /// `R`: the band is `R + 1` cells thick; the interface is at depth `-R`.
    pub r: u32,
    /// `n_deep`: the imaginary particles of the deep.
    pub n_deep: usize,
    pub variant: BandVariant,
}

/// What the band part of one correction did.
#[derive(Clone, Debug)]
pub struct BandCorrection<const D: usize> {
    pub variant: BandVariant,
    /// `alpha_<=-R`: the room in the band interface and the deep before the step.
    pub alpha: i64,
    /// `n*_in`, `n*_out`: moves into and out of `C_<=-R` in the first solve `b*`
    /// (for `full`, in its only solve).
    pub n_in: usize,
    pub n_out: usize,
    /// `s_in = n*_out - n*_in + alpha`, `s_out = n*_in - n*_out` (sec. band_con2).
    pub s_in: i64,
    pub s_out: i64,
    /// Particles that had to be moved into (`s_out < 0`) or out of (`s_in < 0`) `C_<=-R`.
    pub n_move: usize,
    /// `paths`: paths applied, paths found by all calls of alg. find (each call stops once it
    /// has as many as are still needed), and those calls.
    /// `exact-paths`: the flow solver's augmenting paths (each moves one particle across).
    pub paths_applied: usize,
    pub paths_found: usize,
    pub find_calls: usize,
    /// Time of the second solve (`one-way`) or of the path search (`paths`).
    pub second_time: Duration,
    /// `sum |x_j - x_hat_j|^2` after the first solve and of the final positions.
    pub first_objective: f64,
    pub objective: f64,
    /// Eq. problem3's objective (`sigma_solid_obj` included) of the final positions: what the
    /// variants are compared by.
    pub cost: f64,
    /// `n_in - n_out` of the final positions; the band constraint asks `0 <= net <= alpha`.
    pub net_in: i64,
    /// Set when the variant could not meet the band constraint (a finding: the paper says it
    /// always can).
    pub failure: Option<BandFailure>,
    /// The paths applied (`paths`), or the cell changes of the second step as paths
    /// (`exact-paths`, [`super::exact_paths::paths_of`]).
    pub paths: Vec<BandPath<D>>,
    /// With cross-checking: the final `cost` of every other variant on the same problem (the
    /// integer programs only on small problems, see [`ILP_CROSS_CHECK_CANDIDATES`]).
    pub other_costs: Vec<(BandVariant, Result<f64, VariantFailure>)>,
}

impl<const D: usize> BandCorrection<D> {
    /// The report after the first solve: its moves in and out of `C_<=-R` and its objective.
    fn new(variant: BandVariant, alpha: i64, (n_in, n_out): (usize, usize), first: f64) -> Self {
        let (s_in, s_out) = (
            n_out as i64 - n_in as i64 + alpha,
            n_in as i64 - n_out as i64,
        );
        Self {
            variant,
            alpha,
            n_in,
            n_out,
            s_in,
            s_out,
            n_move: (-s_in).max(-s_out).max(0) as usize,
            paths_applied: 0,
            paths_found: 0,
            find_calls: 0,
            second_time: Duration::ZERO,
            first_objective: first,
            objective: 0.0,
            cost: 0.0,
            net_in: 0,
            failure: None,
            paths: vec![],
            other_costs: vec![],
        }
    }
}

/// Cross-checking runs the variants that need integer programs only on problems with at most
/// this many candidates: microlp's branch and bound takes minutes on larger ones.
pub const ILP_CROSS_CHECK_CANDIDATES: usize = 50_000;

/// Why a band correction did not keep the band constraint the way its variant should.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BandFailure {
    /// `one-way`'s second solve failed (the paper says it cannot): corrected along paths.
    #[error("one-way second solve failed ({why}); corrected along {applied} paths instead")]
    OneWaySolve { why: SolveError, applied: usize },
    #[error("alg. find found only {applied} of the {needed} paths needed")]
    TooFewPaths { applied: usize, needed: usize },
    #[error("exact second step failed ({0}); b* kept")]
    ExactSecondStep(SolveError),
    #[error("the band constraint 0 <= n_in - n_out = {net_in} <= alpha = {alpha} does not hold")]
    ConstraintBroken { net_in: i64, alpha: i64 },
}

/// Why a variant gave no cost when cross-checked against the others.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VariantFailure {
    #[error(transparent)]
    Fallback(#[from] Fallback),
    #[error(transparent)]
    Band(#[from] BandFailure),
}

/// The first solve `b*` of eq. problem3 (for `full`, its only solve, with eq. band_con), and
/// why it failed if it did: every particle then keeps its previous cell.
fn first_solve<const D: usize>(
    p: &CorrectionProblem<D>,
    variant: BandVariant,
    alpha: i64,
    solver: super::Solver,
) -> (Solved, Option<Fallback>) {
    let first = match variant {
        BandVariant::Full => solve_full(p, alpha).map(|choice| Solved {
            choice,
            work: FlowStats::default(),
            prices: None,
            sink_price: 0.0,
        }),
        _ => solver.solve(&p.assignment, None),
    };
    match first {
        Ok(s) => (s, None),
        Err(why) => {
            let solver = match variant {
                BandVariant::Full => "band ILP (simplex)",
                _ => solver.name(),
            };
            let stay = Solved {
                choice: p.stay.clone(),
                work: FlowStats::default(),
                prices: None,
                sink_price: 0.0,
            };
            (stay, Some(Fallback { solver, why }))
        }
    }
}

/// `alpha_<=-R = alpha_-R + alpha_<-R`: particles missing from the band interface cells of the
/// previous markings plus the room in the deep, `mu |C_<-R| - n_deep` (sec. band_con). Over
/// the lines of fluid, in parallel (the sum is of integers: exact in any order).
pub fn room_at_or_below_interface(previous: &Markings, r: u32, mu: u32, n_deep: usize) -> i64 {
    let room = |c: usize| match previous.level(c, r) {
        DepthLevel::Interface => mu as i64 - previous.count[c] as i64,
        DepthLevel::Deep => mu as i64,
        _ => 0,
    };
    let lines = previous.fluid_ranges().par_iter();
    let room: i64 = lines.map(|l| l.clone().map(room).sum::<i64>()).sum();
    room - n_deep as i64
}

/// `(n_in, n_out)` of a choice: its candidates in `gamma_in` and in `gamma_out`.
pub fn flows<const D: usize>(p: &CorrectionProblem<D>, choice: &[u32]) -> (usize, usize) {
    choice
        .iter()
        .fold((0, 0), |(i, o), &k| match p.band_sign[k as usize] {
            1 => (i + 1, o),
            -1 => (i, o + 1),
            _ => (i, o),
        })
}

/// `n_in - n_out` of final positions against the previous ones.
pub fn net_into_interface<const D: usize>(
    grid: &Grid<D>,
    x_bar: &[Vector<D>],
    pos: &[Vector<D>],
    previous: &Markings,
    r: u32,
) -> i64 {
    let low = |x: &Vector<D>| previous.at_or_below_interface(grid.cell_index_of(x), r);
    x_bar
        .iter()
        .zip(pos)
        .map(|(a, b)| match (low(a), low(b)) {
            (false, true) => 1,
            (true, false) => -1,
            _ => 0,
        })
        .sum()
}

/// `sum |x - x_hat|^2`.
pub fn objective<const D: usize>(pos: &[Vector<D>], x_hat: &[Vector<D>]) -> f64 {
    pos.iter()
        .zip(x_hat)
        .map(|(x, h)| (x - h).norm_squared())
        .sum()
}

/// `full`: eq. problem3 with eq. band_con_update (in the problem's bounds) and eq. band_con
/// (`0 <= sum gamma_in - sum gamma_out <= alpha`) as an integer program.
pub fn solve_full<const D: usize>(
    p: &CorrectionProblem<D>,
    alpha: i64,
) -> Result<Vec<u32>, SolveError> {
    let terms = (0..p.band_sign.len())
        .filter(|&k| p.band_sign[k] != 0)
        .map(|k| (k, p.band_sign[k] as f64))
        .collect();
    let side = SideConstraint {
        terms,
        min: 0.0,
        max: alpha as f64,
    };
    super::valid(&p.assignment, lp::solve_with(&p.assignment, &[side])?)
}

/// `one-way`, second step (sec. band_con2). Given `b*` with `s_in < 0`: keep the moves out of
/// `C_<=-R` that `b*` made and block the others (eq. band_con2.a), block moves in that `b*` did
/// not make (eq. band_con2.b) and let exactly `n*_out + alpha` of `b*`'s moves in happen
/// (eq. band_con2.c). With `s_out < 0` the roles swap (eq. band_con3): keep `b*`'s moves in and
/// let exactly `n*_in` of its moves out happen. Returns `b*` unchanged when both are >= 0.
pub fn solve_one_way<const D: usize>(
    p: &CorrectionProblem<D>,
    b_star: &[u32],
    alpha: i64,
) -> Result<Vec<u32>, SolveError> {
    let (n_in, n_out) = flows(p, b_star);
    let (s_in, s_out) = (
        n_out as i64 - n_in as i64 + alpha,
        n_in as i64 - n_out as i64,
    );
    let (limited, fixed, count) = if s_in < 0 {
        (1, -1, n_out as i64 + alpha)
    } else if s_out < 0 {
        (-1, 1, n_in as i64)
    } else {
        return Ok(b_star.to_vec());
    };
    let a = &p.assignment;
    let sign = |k: usize| p.band_sign[k];
    let (reduced, original) = a.restrict(|i, k| {
        let chosen = b_star[i] as usize;
        if sign(chosen) == fixed {
            // eq. band_con2.a / band_con3.a: this particle's move is fixed.
            return k == chosen;
        }
        // Blocked: moves in the fixed direction that b* did not make, and moves in the
        // limited direction that b* did not make (eq. band_con2.a-b / band_con3.a-b).
        sign(k) == 0 || k == chosen
    });
    let terms: Vec<(usize, f64)> = (0..original.len())
        .filter(|&k| sign(original[k] as usize) == limited)
        .map(|k| (k, 1.0))
        .collect();
    let side = SideConstraint {
        terms,
        min: count as f64,
        max: count as f64,
    };
    let choice = lp::solve_with(&reduced, &[side])?;
    super::valid(a, choice.iter().map(|&k| original[k as usize]).collect())
}

/// The result of a band correction.
pub struct BandOutcome<const D: usize> {
    /// Final positions `x`.
    pub pos: Vec<Vector<D>>,
    pub report: BandCorrection<D>,
    /// The first (or, for `full`, the only) solve: its time, augmenting paths and, when the
    /// solver failed and every particle kept its cell, why.
    pub solve_time: Duration,
    pub augmentations: usize,
    pub fallback: Option<Fallback>,
    /// Eq. problem3's objective (`sigma_solid_obj` included) at the first solve's choice: the
    /// value an LP solver finds for the exported problem (but for `full`).
    pub first_cost: f64,
    /// `exact-paths`: the second step's problem and its optimum, for export.
    pub second_step: Option<(SecondStep, f64)>,
}

/// Corrects the advected positions `x_hat` with the band variant of `ctx`: the first solve of
/// eq. problem3 by `solver` (for `full`, the integer program), then the variant's second step.
pub fn correct_band<const D: usize>(
    sc: &BandScene<'_, D>,
    p: &CorrectionProblem<D>,
    ctx: BandContext,
    solver: super::Solver,
) -> BandOutcome<D> {
    let (grid, x_hat) = (sc.grid, sc.x_hat);
    // Negative only if an earlier step left excess without room (reported there): then no
    // particle may enter.
    let alpha = room_at_or_below_interface(sc.previous, ctx.r, sc.mu, ctx.n_deep).max(0);
    let t0 = Instant::now();
    let (first, fallback) = first_solve(p, ctx.variant, alpha, solver);
    let solve_time = t0.elapsed();
    let choice = &first.choice;
    let first_cost = p.assignment.objective(choice);
    let flows = flows(p, choice);
    let mut pos: Vec<Vector<D>> = positions(grid, p, choice, x_hat);
    let mut rep = BandCorrection::new(ctx.variant, alpha, flows, objective(&pos, x_hat));
    let direction = PathDirection::of(rep.s_in);
    let mut second_step = None;
    let t1 = Instant::now();
    match ctx.variant {
        _ if rep.n_move == 0 => {}
        BandVariant::Full => {}
        BandVariant::OneWay => {
            match solve_one_way(p, choice, alpha) {
                Ok(c) => pos = positions(grid, p, &c, x_hat),
                Err(why) => {
                    // The paper says the second solve is always feasible; if it is not (or
                    // times out), correct b* along paths instead.
                    let o = PathSearch::new(sc, ctx.r, direction).push(&mut pos, rep.n_move);
                    let applied = o.applied;
                    rep.failure = Some(BandFailure::OneWaySolve { why, applied });
                }
            }
        }
        BandVariant::Paths => {
            let o = PathSearch::new(sc, ctx.r, direction).push(&mut pos, rep.n_move);
            rep.paths_applied = o.applied;
            rep.paths_found = o.found;
            rep.find_calls = o.find_calls;
            rep.paths = o.paths;
            if o.applied < rep.n_move {
                rep.failure = Some(BandFailure::TooFewPaths {
                    applied: o.applied,
                    needed: rep.n_move,
                });
            }
        }
        BandVariant::ExactPaths => {
            let bounds = (ctx.r, sc.mu);
            let step = SecondStep::build(p, choice, sc.previous, bounds, direction, rep.n_move);
            let solved = step.and_then(|s| {
                let (c, stats) = s.solve(choice, first.prices.as_deref())?;
                Ok((s, c, stats))
            });
            match solved {
                Ok((s, c, stats)) => {
                    pos = positions(grid, p, &c, x_hat);
                    rep.paths = super::exact_paths::paths_of(grid, p, choice, &c);
                    rep.paths_applied = stats.augmentations;
                    second_step = Some((s, p.assignment.objective(&c)));
                }
                Err(e) => rep.failure = Some(BandFailure::ExactSecondStep(e)),
            }
        }
    }
    rep.second_time = t1.elapsed();
    rep.net_in = net_into_interface(grid, sc.x_bar, &pos, sc.previous, ctx.r);
    if rep.failure.is_none() && fallback.is_none() && !(0..=alpha).contains(&rep.net_in) {
        rep.failure = Some(BandFailure::ConstraintBroken {
            net_in: rep.net_in,
            alpha,
        });
    }
    rep.objective = objective(&pos, x_hat);
    let (displacement, penalty) = sc.cost_parts(&pos);
    rep.cost = displacement + penalty;
    BandOutcome {
        pos,
        report: rep,
        solve_time,
        augmentations: first.work.augmentations,
        fallback,
        first_cost,
        second_step,
    }
}

/// The positions `xi` of a choice (eq. best_cell_pos).
fn positions<const D: usize>(
    grid: &Grid<D>,
    p: &CorrectionProblem<D>,
    choice: &[u32],
    x_hat: &[Vector<D>],
) -> Vec<Vector<D>> {
    choice
        .par_iter()
        .zip(x_hat)
        .map(|(&k, xh)| p.position(grid, k as usize, xh))
        .collect()
}
