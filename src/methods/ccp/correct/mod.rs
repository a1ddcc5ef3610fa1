//! The paper's correction step (sec. 4-5, alg. flip line 6): after advection, move particles
//! so that no cell holds more than `mu` (inner cells keep at least what they had, solids hold
//! nothing) with the least total squared displacement, eq. problem3.
//!
//! The problem is built once ([`problem::build`]) and solved exactly, by the min-cost-flow
//! solver (default) or by the simplex on the LP relaxation; both read the same data. With the
//! band method (sec. band_method) one of the band variants of [`band`] finishes the step.

pub mod band;
pub mod exact_paths;
pub mod guarantees;
pub mod path_search;
pub mod paths;
pub mod problem;

use crate::grid::{Grid, Vector};
use crate::solvers::min_cost_flow::{self, FlowStats};
use crate::solvers::{lp, mps};
use crate::stages::markings::Markings;
use band::{BandContext, BandCorrection, BandVariant, VariantFailure, ILP_CROSS_CHECK_CANDIDATES};
use paths::BandScene;
use problem::{BuildError, CorrectionProblem, Directions};
use rayon::prelude::*;
use std::time::{Duration, Instant};

/// Which solver corrects the positions (the flag `--solver` names them: `super::settings`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Solver {
    /// [`min_cost_flow`]: successive shortest paths, exact.
    #[default]
    Flow,
    /// [`crate::solvers::lp`]: microlp's simplex on the LP relaxation, the reference.
    Simplex,
}

impl Solver {
    pub const ALL: [Solver; 2] = [Solver::Flow, Solver::Simplex];

    pub fn name(self) -> &'static str {
        match self {
            Solver::Flow => "flow",
            Solver::Simplex => "simplex",
        }
    }

    /// Solves `p`; the flow solver starts from `warm` prices (per bin, relative to the sink)
    /// when given, the simplex ignores them. An answer that breaks a constraint is a failure.
    pub(crate) fn solve(
        self,
        p: &min_cost_flow::BoundedAssignment,
        warm: Option<&[f64]>,
    ) -> Result<Solved, SolveError> {
        let solved = match self {
            Solver::Flow => {
                let cold;
                let prices = match warm {
                    Some(prices) => prices,
                    None => {
                        cold = vec![0.0; p.bins()];
                        &cold
                    }
                };
                min_cost_flow::solve_halved(p, prices, min_cost_flow::HALVING)
            }
            .map(|s| Solved {
                choice: s.choice,
                work: s.stats,
                prices: Some(s.prices),
                sink_price: s.sink_price,
            })
            .map_err(SolveError::from),
            Solver::Simplex => lp::solve(p)
                .map(|choice| Solved {
                    choice,
                    work: FlowStats::default(),
                    prices: None,
                    sink_price: 0.0,
                })
                .map_err(SolveError::from),
        }?;
        p.check(&solved.choice)?;
        Ok(solved)
    }
}

/// `choice` if it is an assignment of `p`: a solver's answer that breaks a constraint counts as
/// the solver's failure.
pub(crate) fn valid(
    p: &min_cost_flow::BoundedAssignment,
    choice: Vec<u32>,
) -> Result<Vec<u32>, SolveError> {
    p.check(&choice)?;
    Ok(choice)
}

/// Why a solve of the correction gave no usable assignment.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error(transparent)]
    Flow(#[from] min_cost_flow::Infeasible),
    #[error(transparent)]
    Simplex(#[from] lp::LpError),
    /// The solver's answer breaks a constraint.
    #[error(transparent)]
    Invalid(#[from] min_cost_flow::InvalidChoice),
    /// `exact-paths`' second step: its sources cannot supply the particles to move.
    #[error("the sources hold {held} particles, fewer than the {needed} to move")]
    TooFewAtSources { held: usize, needed: usize },
}

/// A correction whose (first) solve failed: every particle kept its previous cell.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{solver} solver failed ({why}); particles keep their cells")]
pub struct Fallback {
    /// The solver, as the log names it.
    pub solver: &'static str,
    pub why: SolveError,
}

/// What a solver found: the chosen candidate of every item, the flow solver's work (augmenting
/// paths and nodes settled; zero for the others) and its prices (the dual certificate that
/// `exact-paths` starts from).
pub(crate) struct Solved {
    pub choice: Vec<u32>,
    pub work: FlowStats,
    pub prices: Option<Vec<f64>>,
    /// The sink's price, which `prices` are relative to.
    pub sink_price: f64,
}

/// The flow solver's prices of the last correction per grid cell, relative to the sink: the
/// next step's problem has the same cells and particles one step further, so these prices,
/// scaled by [`WARM_PRICE_SCALE`], are its warm start ([`min_cost_flow::solve_warm`]). A warm
/// start changes the solver's work, not the optimum.
#[derive(Clone, Debug, Default)]
pub struct PriceMemory {
    /// Per cell up to the last solve's highest bin cell, its price; 0 off its bins.
    cell_price: Vec<f64>,
    /// The cells given a price (those to set back to 0 before the next solve's, rather than
    /// the whole prefix, which covers nearly the box under a pool).
    priced: Vec<usize>,
}

/// How much of the last step's prices a warm start takes. At full strength they overshoot:
/// the last correction left its particles on the faces of their cells, so this step's moves
/// are cheaper than last step's were. Measured on dam-3d without the band (flow solver's
/// settled nodes, all steps summed; `cellflip run dam-3d --method ccp --band none`): at 50^3
/// over 20 steps 3.99 M cold, 3.14 M at scale 1, 3.03 M at 0.5, 3.39 M at 0.25; at 100^3 over
/// 12 steps 28.3 M cold, 17.3 M at 0.5 (solver time 10.3 s -> 7.4 s), 16.4 M at 0.7 and
/// 19.5 M at 0.35, both slower than 0.5 (9.5 s and 7.5 s: more augmenting paths). It can lose
/// while the column starts to fall: at 140^3 10-17% more at steps 3-5, 25-45% less at 6-10.
pub const WARM_PRICE_SCALE: f64 = 0.5;

impl PriceMemory {
    /// The prices remembered, per cell (empty: none), for a checkpoint.
    pub fn cell_prices(&self) -> &[f64] {
        &self.cell_price
    }

    /// The memory of a checkpoint's [`cell_prices`](Self::cell_prices).
    pub fn from_cell_prices(cell_price: Vec<f64>) -> Self {
        let priced = (0..cell_price.len()).collect();
        Self { cell_price, priced }
    }

    /// The warm prices of the bins `bin_cell` (0, the sink's price, for a cell that had none),
    /// or `None` before the first solve and after one without prices.
    fn prices_of(&self, bin_cell: &[usize]) -> Option<Vec<f64>> {
        let price = |&c: &usize| WARM_PRICE_SCALE * self.cell_price.get(c).copied().unwrap_or(0.0);
        (!self.cell_price.is_empty()).then(|| bin_cell.iter().map(price).collect())
    }

    /// Remembers the prices of `solved` (a problem with bins `bin_cell`), or forgets them all
    /// when it has none (the simplex, or a failed solve).
    fn remember(&mut self, bin_cell: &[usize], solved: Option<&Solved>) {
        for c in self.priced.drain(..) {
            self.cell_price[c] = 0.0;
        }
        let Some(Solved {
            prices: Some(prices),
            sink_price,
            ..
        }) = solved
        else {
            self.cell_price.clear();
            return;
        };
        let cells = bin_cell.iter().max().map_or(0, |&c| c + 1);
        self.cell_price.resize(cells, 0.0);
        for (&c, &p) in bin_cell.iter().zip(prices) {
            self.cell_price[c] = p - sink_price;
        }
        self.priced.extend_from_slice(bin_cell);
    }
}

/// `|objective(choice) - reference| / max(1, |reference|)` for a valid `choice` of `p`.
fn relative_gap(p: &min_cost_flow::BoundedAssignment, choice: &[u32], reference: f64) -> f64 {
    (p.objective(choice) - reference).abs() / reference.abs().max(1.0)
}

/// How the correction is set up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CorrectionSettings {
    pub solver: Solver,
    pub directions: Directions,
    /// Also solve with the other solver and report the objectives' relative difference.
    pub cross_check: bool,
}

impl Default for CorrectionSettings {
    fn default() -> Self {
        Self {
            solver: Solver::Flow,
            directions: Directions::VonNeumann,
            cross_check: false,
        }
    }
}

/// What one correction did.
#[derive(Clone, Debug, Default)]
pub struct CorrectionReport<const D: usize> {
    /// The displacement: `sum |x - x_hat|^2` over the particles that end outside
    /// `C_new_solid`.
    pub objective: f64,
    /// The solid penalty: `sum sigma_solid_obj` over the particles that end in `C_new_solid`
    /// (eq. solid_penalty2; 0 without obstacles). With `objective`, what the solver minimised.
    pub penalty: f64,
    /// Cells holding more than `mu` particles after advection, before the correction.
    pub overfull_before: usize,
    pub solver_time: Duration,
    /// Augmenting paths of the flow solver.
    pub augmentations: usize,
    /// Set when the solver failed and every particle stayed in its previous cell.
    pub fallback: Option<Fallback>,
    /// `|objective(other solver) - objective| / max(1, |objective|)`, with `cross_check`; with
    /// `exact-paths`, of its second step (on small problems, when it had particles to move).
    pub cross_check: Option<Result<f64, SolveError>>,
    /// Time the other solver took on the same problem, with `cross_check`.
    pub cross_check_time: Option<Duration>,
    /// `(x_hat, x)` of the particles that end in another cell than the one their advected
    /// position is in.
    pub moves: Vec<(Vector<D>, Vector<D>)>,
    /// The problem as free-format MPS, when asked for.
    pub mps: Option<String>,
    /// `exact-paths` when it had particles to move: its second-step problem as MPS, when asked.
    pub second_mps: Option<String>,
    /// The band correction, with the band method.
    pub band: Option<BandCorrection<D>>,
}

impl<const D: usize> CorrectionReport<D> {
    /// Eq. problem3's objective with `sigma_solid_obj`: the displacement plus the penalty.
    pub fn total(&self) -> f64 {
        self.objective + self.penalty
    }
}

/// Corrects `pos` (the advected positions `x_hat` on entry, `x` on return) given the previous
/// positions `x_bar` and markings, with the band method when `band` is given. A solver failure
/// keeps every particle in its previous cell (always feasible) and says why in the report; a
/// problem that cannot be built is a bug and comes back as an error.
#[allow(clippy::too_many_arguments)]
pub fn correct<const D: usize>(
    grid: &Grid<D>,
    x_bar: &[Vector<D>],
    pos: &mut [Vector<D>],
    previous: &Markings,
    solid: &[bool],
    mu: u32,
    settings: &CorrectionSettings,
    band: Option<BandContext>,
    penalty: Option<&[f64]>,
    want_mps: bool,
    memory: &mut PriceMemory,
) -> Result<CorrectionReport<D>, BuildError> {
    let problem = problem::build(
        grid,
        x_bar,
        pos,
        previous,
        solid,
        mu,
        settings.directions,
        band.map(|b| b.r),
        penalty,
    )?;
    let mut rep = CorrectionReport {
        overfull_before: overfull_cells(grid, pos, mu),
        ..Default::default()
    };
    match band {
        Some(ctx) => {
            let x_hat = pos.to_vec();
            let scene = BandScene {
                grid,
                x_bar,
                x_hat: &x_hat,
                previous,
                solid,
                penalty,
                mu,
            };
            let (first_cost, second) = correct_band(&scene, &problem, pos, settings, ctx, &mut rep);
            if want_mps {
                rep.mps = Some(band_mps(&problem, &rep, first_cost, settings, ctx.variant));
                rep.second_mps = second.map(|(s, optimum)| second_step_mps(&s, optimum));
            }
        }
        None => {
            let choice = solve(&problem, settings, penalty, &mut rep, memory);
            if want_mps {
                let cost = problem.assignment.objective(&choice);
                let why = rep.fallback.as_ref().map(Fallback::to_string);
                let comment = objective_comment(cost, settings.solver, why.as_deref());
                rep.mps = Some(mps::write(
                    &problem.assignment,
                    "cellflip-correction",
                    &[comment],
                ));
            }
            apply(grid, &problem, &choice, pos, &mut rep);
        }
    }
    Ok(rep)
}

/// Eq. problem3 without the band: the solver's choice of candidate per particle (every
/// particle's previous cell if the solver fails), its objective's two parts, and with
/// `cross_check` the other solver's answer on the same problem.
fn solve<const D: usize>(
    problem: &CorrectionProblem<D>,
    settings: &CorrectionSettings,
    penalty: Option<&[f64]>,
    rep: &mut CorrectionReport<D>,
    memory: &mut PriceMemory,
) -> Vec<u32> {
    let t0 = Instant::now();
    let warm = memory.prices_of(&problem.bin_cell);
    let solved = settings.solver.solve(&problem.assignment, warm.as_deref());
    rep.solver_time = t0.elapsed();
    memory.remember(&problem.bin_cell, solved.as_ref().ok());
    let choice = match solved {
        Ok(s) => {
            rep.augmentations = s.work.augmentations;
            s.choice
        }
        Err(why) => {
            rep.fallback = Some(Fallback {
                solver: settings.solver.name(),
                why,
            });
            problem.stay.clone()
        }
    };
    let a = &problem.assignment;
    let ends = choice.iter().map(|&k| {
        let k = k as usize;
        (problem.bin_cell[a.cand_bin[k] as usize], a.cand_cost[k])
    });
    (rep.objective, rep.penalty) = objective_parts(ends, penalty);
    if settings.cross_check {
        let other = match settings.solver {
            Solver::Flow => Solver::Simplex,
            Solver::Simplex => Solver::Flow,
        };
        let t1 = Instant::now();
        let other_result = other.solve(&problem.assignment, None);
        rep.cross_check_time = Some(t1.elapsed());
        let total = rep.total();
        rep.cross_check =
            Some(other_result.map(|s| relative_gap(&problem.assignment, &s.choice, total)));
    }
    choice
}

/// Splits eq. problem3's objective by where the particles end: the displacement `sum |x -
/// x_hat|^2` of those outside `C_new_solid`, and the penalty `sum sigma_solid_obj` (their
/// cell's) of those in it. `ends` yields each particle's final cell and squared displacement.
pub(super) fn objective_parts(
    ends: impl Iterator<Item = (usize, f64)>,
    penalty: Option<&[f64]>,
) -> (f64, f64) {
    ends.fold((0.0, 0.0), |(d, s), (c, cost)| {
        match penalty.map(|p| p[c]) {
            Some(p) if p > 0.0 => (d, s + p),
            _ => (d + cost, s),
        }
    })
}

/// An exported problem's objective line: eq. problem3's objective (`sigma_solid_obj`
/// included) at the solver's optimum, or, when the solver failed, at the fallback (every
/// particle in its previous cell) and why.
fn objective_comment(cost: f64, solver: Solver, fallback: Option<&str>) -> String {
    match fallback {
        None => format!("optimal objective {cost:.17e} ({} solver)", solver.name()),
        Some(why) => format!("fallback objective {cost:.17e} ({why})"),
    }
}

/// The band method's problem as MPS: eq. problem3 with the bounds of eq. band_con_update,
/// without the band row, and `first_cost`, its objective at the first solve: the optimum (not
/// for `full`, whose solve has the band row) or the fallback's.
fn band_mps<const D: usize>(
    problem: &CorrectionProblem<D>,
    rep: &CorrectionReport<D>,
    first_cost: f64,
    settings: &CorrectionSettings,
    variant: BandVariant,
) -> String {
    let b = rep.band.as_ref().expect("band report");
    let mut comment = vec![format!(
        "band method ({}): eq. problem3 with the bounds of eq. band_con_update; the band row \
         eq. band_con (0 <= in - out <= alpha = {}) is not included",
        variant.name(),
        b.alpha
    )];
    if variant != BandVariant::Full || rep.fallback.is_some() {
        let fallback = rep.fallback.as_ref().map(Fallback::to_string);
        comment.push(objective_comment(
            first_cost,
            settings.solver,
            fallback.as_deref(),
        ));
    }
    mps::write(&problem.assignment, "cellflip-correction", &comment)
}

/// `exact-paths`' second-step problem as MPS (see [`exact_paths`]) with its optimum.
fn second_step_mps(step: &exact_paths::SecondStep, optimum: f64) -> String {
    let comment = [
        "exact-paths: the band method's second step (sources lose n_move particles, sinks gain \
         up to mu, other cells keep their count; ghost items count the particles that leave)"
            .to_string(),
        objective_comment(optimum, Solver::Flow, None),
    ];
    mps::write(&step.problem, "cellflip-band-second-step", &comment)
}

/// The band method's correction: the variant of `ctx`, and with cross-checking every other
/// variant on the same problem, for their costs (the integer programs only on small problems).
/// Returns eq. problem3's objective at the first solve, for the exported problem, and the
/// second step of `exact-paths` with its optimum.
fn correct_band<const D: usize>(
    scene: &BandScene<'_, D>,
    problem: &CorrectionProblem<D>,
    pos: &mut [Vector<D>],
    settings: &CorrectionSettings,
    ctx: BandContext,
    rep: &mut CorrectionReport<D>,
) -> (f64, Option<(exact_paths::SecondStep, f64)>) {
    let run = |variant| {
        let ctx = BandContext { variant, ..ctx };
        band::correct_band(scene, problem, ctx, settings.solver)
    };
    let out = run(ctx.variant);
    let mut report = out.report;
    if settings.cross_check {
        let small = problem.assignment.cand_bin.len() <= ILP_CROSS_CHECK_CANDIDATES;
        let others = BandVariant::ALL.into_iter().filter(|&v| v != ctx.variant);
        for v in others.filter(|v| small || !v.needs_ilp()) {
            let o = run(v);
            let result = match (o.fallback, o.report.failure) {
                (Some(e), _) => Err(VariantFailure::from(e)),
                (None, Some(e)) => Err(VariantFailure::from(e)),
                (None, None) => Ok(o.report.cost),
            };
            report.other_costs.push((v, result));
        }
        if let Some((step, optimum)) = out.second_step.as_ref().filter(|_| small) {
            let t0 = Instant::now();
            let simplex = lp::solve(&step.problem).map_err(SolveError::from);
            rep.cross_check_time = Some(t0.elapsed());
            let gap = |c: Vec<u32>| relative_gap(&step.problem, &c, *optimum);
            rep.cross_check = Some(simplex.and_then(|c| valid(&step.problem, c)).map(gap));
        }
    }
    pos.copy_from_slice(&out.pos);
    rep.solver_time = out.solve_time;
    rep.augmentations = out.augmentations;
    rep.fallback = out.fallback;
    rep.band = Some(report);
    (rep.objective, rep.penalty) = scene.cost_parts(pos);
    let (grid, x_hat) = (scene.grid, scene.x_hat);
    rep.moves = x_hat
        .iter()
        .zip(pos.iter())
        .filter(|(h, x)| grid.cell_index_of(h) != grid.cell_index_of(x))
        .map(|(h, x)| (*h, *x))
        .collect();
    (out.first_cost, out.second_step)
}

/// How many cells hold more than `mu` of `pos`: each is counted as its count passes `mu`, so
/// that no pass visits the cells.
fn overfull_cells<const D: usize>(grid: &Grid<D>, pos: &[Vector<D>], mu: u32) -> usize {
    let mut count = vec![0u32; grid.num_cells()];
    let mut overfull = 0;
    for x in pos {
        let n = &mut count[grid.cell_index_of(x)];
        *n += 1;
        overfull += usize::from(*n == mu + 1);
    }
    overfull
}

fn apply<const D: usize>(
    grid: &Grid<D>,
    problem: &CorrectionProblem<D>,
    choice: &[u32],
    pos: &mut [Vector<D>],
    rep: &mut CorrectionReport<D>,
) {
    // In parallel, keeping particle order: the move of each particle sent to another cell.
    rep.moves = pos
        .par_iter_mut()
        .zip(choice)
        .filter_map(|(x, &k)| {
            let x_hat = *x;
            *x = problem.position(grid, k as usize, &x_hat);
            (grid.cell_index_of(x) != grid.cell_index_of(&x_hat)).then_some((x_hat, *x))
        })
        .collect();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A solve with prices `p` (relative to a sink priced 1).
    fn solved(p: &[f64]) -> Solved {
        Solved {
            choice: vec![],
            work: FlowStats::default(),
            prices: Some(p.iter().map(|p| p + 1.0).collect()),
            sink_price: 1.0,
        }
    }

    #[test]
    fn the_price_memory_holds_the_last_solve_s_prices_alone() {
        let mut m = PriceMemory::from_cell_prices(vec![0.0, 7.0, 0.0, 8.0]);
        m.remember(&[2, 5, 9], Some(&solved(&[1.0, 2.0, 3.0])));
        let first = [0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0];
        assert_eq!(m.cell_prices(), first);
        m.remember(&[1, 5], Some(&solved(&[4.0, 5.0])));
        assert_eq!(m.cell_prices(), [0.0, 4.0, 0.0, 0.0, 0.0, 5.0]);
        let h = WARM_PRICE_SCALE;
        assert_eq!(
            m.prices_of(&[1, 3, 5, 40]),
            Some(vec![4.0 * h, 0.0, 5.0 * h, 0.0])
        );
        m.remember(&[3, 4, 8], Some(&solved(&[6.0, 7.0, 8.0])));
        assert_eq!(
            m.cell_prices(),
            [0.0, 0.0, 0.0, 6.0, 7.0, 0.0, 0.0, 0.0, 8.0]
        );
        m.remember(&[1, 2], None);
        assert_eq!(m.cell_prices(), [0.0; 0]);
        assert_eq!(m.prices_of(&[1]), None);
        m.remember(&[0, 2], Some(&solved(&[9.0, 10.0])));
        assert_eq!(m.cell_prices(), [9.0, 0.0, 10.0]);
    }
}
