//! Entropy-regularised optimal transport between points of equal volume and the cells of a
//! regular grid that may be partly empty, by Sinkhorn's scaling iterations (Cuturi 2013), with
//! two models of the empty part ("air") of a cell.
//!
//! Points `p` (volume `V_p` each) and cells `j` (centre `x_j`, capacity `V_j`): the plan `T`
//! minimises
//!
//! `sum T_pj |x_p - x_j|^2 + eps sum T_pj (log T_pj - 1) + A(a)`
//!
//! subject to `sum_j T_pj = V_p` for every point and `sum_p T_pj + a_j = V_j` for every cell,
//! with an air slack `a_j >= 0` whose cost `A` is one of ([`Air`]):
//!
//! - **capacity**: `A = 0`, air is free (the partial transport of Benamou et al. 2015, sec.
//!   5.2): a cell holds at most its capacity;
//! - **baseline**: `A = eta eps sum_j KL(a_j | b_j)`, `KL(a | b) = a log(a / b) - a + b`, which
//!   pulls the air towards a given baseline `b_j` (`0 <= b_j <= V_j`) with weight `eta`.
//!
//! **The dual and its updates.** With multipliers `eps f_p` (rows) and `eps g_j` (columns),
//! stationarity in `T_pj` gives `|x_p - x_j|^2 + eps log T_pj - eps f_p - eps g_j = 0`, so
//! `T_pj = u_p K_pj v_j` with `u_p = e^(f_p)`, `v_j = e^(g_j)`, `K_pj = e^(-|x_p - x_j|^2 / eps)`.
//! Block-coordinate ascent on the dual alternates:
//!
//! - rows: `u_p = V_p / sum_j K_pj v_j` (every point's volume exact);
//! - columns, with `C_j = sum_p K_pj u_p` (so that `sum_p T_pj = v_j C_j`):
//!   - capacity: the complementary slackness of `a_j >= 0` with multiplier `-eps g_j >= 0`
//!     gives `v_j = min(1, V_j / C_j)` (a cell is either full, `v_j < 1`, or holds its
//!     kernels as they come, `v_j = 1`);
//!   - baseline: stationarity in `a_j`, `eta eps log(a_j / b_j) - eps g_j = 0`, gives
//!     `a_j = b_j v_j^(1 / eta)`, and the column constraint becomes
//!     `v_j C_j + b_j v_j^(1 / eta) = V_j`. At `eta = 1` it is closed-form,
//!     `v_j = V_j / (C_j + b_j)`; otherwise its left side is increasing and, as a function of
//!     `g_j`, convex in `log`, so Newton's method on `log(C_j e^g + b_j e^(g / eta)) = log V_j`
//!     from the upper bound `g = min(log(V_j / C_j), eta log(V_j / b_j))` converges
//!     monotonically. Deep inside the liquid (`b_j = 0`) the cell must be exactly full; far
//!     outside (`b_j = V_j`) a cell reached by little kernel stays nearly empty; a larger
//!     `eta` holds the air closer to `b_j`.
//!
//! The iteration stops, after a row update, when every column meets its marginal to a relative
//! `delta`: for capacity, `|v_j C_j / V_j - 1|` for a full cell and `v_j C_j / V_j - 1` above
//! the capacity for the others; for the baseline, `|(v_j C_j + a_j) / V_j - 1|`.
//!
//! **Over-relaxation (ours).** Past the first iteration both updates move beyond their exact
//! values, `g <- g + omega (g* - g)` on the scalings' logs (Thibault et al. 2021): the columns
//! by 3/2, the rows by [`ROW_OMEGA`]. The pass over the rows sums the columns of both the
//! exact row scalings and the relaxed ones, so the stopping test is on the plan whose rows
//! are exact, and that is the plan a solve returns: every point's volume exact. An error that
//! grows after [`RELAXED_START`] iterations ends the relaxation for the solve (plain Sinkhorn,
//! which converges from any start).
//!
//! **How it is computed.** The kernel is cut where `|x_p - x_j|^2 / eps` exceeds
//! [`KERNEL_CUTOFF`], so every point sees only the cells of a ball of radius
//! `sqrt(KERNEL_CUTOFF eps)`. On the regular grid `K_pj` is a product of per-axis factors
//! `e^(-(x_p,k - x_j,k)^2 / eps)`: each point computes `d (2 r + 1)` exponentials once per
//! solve and keeps them (in single precision), and every iteration rebuilds its row from them,
//! a sparse matrix-vector product each way ([`kernel`]; Qu et al.'s "localized Gaussian
//! convolutions"). The scalings are kept as `u`, `v` rather than their logs: with the
//! cut, every kept `K_pj` is at least `1e-12`, far inside the range of `f64`. Where the
//! marginals cannot both be met (points whose balls reach less free volume than they hold), the
//! scalings run off geometrically, some towards zero and some towards infinity; the iteration
//! stops, as at its cap, before a column scaling leaves [`SCALING_RANGE`], returning the plan
//! of exact rows it has ([`Transport::out_of_range`]), so that the logs need not be kept (a
//! warm start from such a plan starts cold). A row scaling that is not finite for other
//! reasons is reported ([`SinkhornError::Diverged`]). Columns are summed by scattering
//! chunks of spatially sorted points (their size set by the point count) into their own
//! windows of cells, added in chunk order: results are the same whatever the thread count. A
//! wave of chunks at a time holds its windows, so that the windows held do not grow with the
//! points times a plane of cells. A solve is a few dozen such passes one after another, each
//! over a 2D problem about as long as a sleeping rayon worker takes to wake: its caller may
//! keep the workers awake through it ([`crate::solvers::awake::Awake`]).
//! A solve may start from the previous one's plan ([`Transport::solve`]): from its scalings,
//! the points' carried with them, and into its storage.
//!
//! **What a solve costs of the grid.** Only the cells near the points: the cells within the
//! kernel's reach of a point's cell (the cube of side `2 ceil(r / h) + 1` around it, each line
//! of cells along axis 0 as one span) are numbered densely, and the reached cells among them
//! are the plan's slots. A cell's air baseline is asked for
//! only where some point reaches ([`AirCost`]). What a solve reads of the whole grid is a
//! span per line of cells and a flag per cell (free or blocked), which its owner keeps up.

mod kernel;

use crate::grid::{Grid, Vector};
pub use kernel::Summand;
use kernel::{ByRows, Kernel, RowUpdate};
use rayon::prelude::*;
use std::ops::Range;

/// The kernel is cut where `|x_p - x_j|^2 / eps` exceeds this: `exp(-27.63) = 1e-12`, far
/// below the tolerances `delta` the iteration is run to.
pub const KERNEL_CUTOFF: f64 = 27.631_021_115_928_547;

/// Iterations over which the column error may grow under over-relaxation (it overshoots
/// before it settles); after them a growing error falls back to plain Sinkhorn.
const RELAXED_START: u32 = 10;

/// A column scaling `v_j` outside `[1 / SCALING_RANGE, SCALING_RANGE]` ends the iteration
/// ([`Transport::out_of_range`]): far beyond any scaling of a problem that can be solved (its
/// `K_pj` are at least `1e-12`), and far enough inside `f64`'s range that the row scalings,
/// which go as their inverse, stay normal too. Found on spiral-2d at 64^2 with the rows
/// relaxed by 27/16 instead of [`ROW_OMEGA`] (2026-11-30, issue 73; not kept): at step 244 a
/// solve with the lid pressing on the liquid ran its scalings off by a factor of about 4.5 an
/// iteration at a column error of 0.32, and overflowed at iteration 408, ending the run.
const SCALING_RANGE: f64 = 1e280;

/// Whether a column scaling is within [`SCALING_RANGE`] (false for NaN).
fn scaling_in_range(v: f64) -> bool {
    (1.0 / SCALING_RANGE..=SCALING_RANGE).contains(&v)
}

/// Slots per task of the column updates.
const SLOTS_PER_TASK: usize = 2048;

/// Values per task of the passes that do a few operations a value (a row update's scalings
/// given back by point, their checks): a 2D problem of a few thousand points does them on one
/// thread, not waking the others for a few microseconds of work (dam-2d spent a fifth of its
/// time in the scheduler, issue 73).
const VALUE_GRAIN: usize = 1 << 13;

/// Newton's method for the baseline column update stops when a step moves `g_j` by less than
/// this (a relative change of `1e-13` in `v_j`, far below any `delta`) ...
const NEWTON_TOLERANCE: f64 = 1e-13;
/// ... or after this many steps (it converges monotonically and quadratically; 60 is never
/// reached in practice and only guards against a non-finite input).
const NEWTON_STEPS: u32 = 60;

/// The over-relaxation factor of the row updates, `u <- u (u* / u)^omega` (ours, measured;
/// docs/benchmarks/powerpic.md): on dam-3d at 48^3, steps 151-160, with the columns at 3/2,
/// rows at 1 (exact), 1.6, 1.7, 1.75 and 1.85 took 19.6, 9.5, 8.2, 10.7 and 9.6 iterations a
/// step; on dam-2d over 3 s, 9.2, 5.7, 5.4, 5.3 and 5.5.
const ROW_OMEGA: f64 = 1.7;

/// How far the iteration goes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SinkhornSettings {
    /// `eps`, the entropic regularisation, in the points' length units squared.
    pub epsilon: f64,
    /// `delta`, the relative marginal error at which the iteration stops.
    pub delta: f64,
    /// The iteration stops here even if `delta` is not met (the result says so).
    pub max_iterations: u32,
}

impl SinkhornSettings {
    /// The kernel's reach: cells farther from a point than this carry none of it.
    pub fn radius(&self) -> f64 {
        (KERNEL_CUTOFF * self.epsilon).sqrt()
    }
}

/// The cost of a cell's empty part (see the module doc), with the baselines `b_j` as `B`: a
/// function of the cell for a solve ([`AirCost`]), one value per slot in its plan.
#[derive(Clone, Debug, PartialEq)]
pub enum Air<B> {
    /// Free: a cell holds at most its capacity.
    Capacity,
    /// `eta eps KL(a_j | b_j)`: the air pulled towards the baseline `b_j`.
    Baseline { eta: f64, baseline: B },
}

/// The air's cost as a solve takes it: `baseline(j)` is cell `j`'s `b_j` (`0 <= b_j <= V_j`),
/// asked for only at the cells some point reaches.
pub type AirCost<'a> = Air<&'a (dyn Fn(usize) -> f64 + Sync)>;

impl<B: Fn(usize) -> f64 + Sync> Air<B> {
    /// This air's cost for a solve.
    pub fn cost(&self) -> AirCost<'_> {
        match self {
            Air::Capacity => Air::Capacity,
            Air::Baseline { eta, baseline } => Air::Baseline {
                eta: *eta,
                baseline,
            },
        }
    }
}

/// The cells points are transported to: a regular grid of cells of side `h` (in the points'
/// units; cell `c` covers `[c h, (c + 1) h)`), each free, with the capacity `V_j = h^d`, or
/// blocked (in a solid), without any.
#[derive(Clone, Debug)]
pub struct TransportGrid<const D: usize> {
    pub grid: Grid<D>,
    pub h: f64,
    free: Vec<bool>,
    free_cells: usize,
}

impl<const D: usize> TransportGrid<D> {
    /// The grid `grid` of cells of side `h`, every cell free.
    pub fn new(grid: Grid<D>, h: f64) -> Self {
        let n = grid.num_cells();
        Self {
            grid,
            h,
            free: vec![true; n],
            free_cells: n,
        }
    }

    pub fn center(&self, j: usize) -> Vector<D> {
        self.grid.center(self.grid.cell_coords(j)) * self.h
    }

    /// `V_j` of a free cell, `h^d`.
    pub fn cell_volume(&self) -> f64 {
        self.h.powi(D as i32)
    }

    pub fn is_free(&self, j: usize) -> bool {
        self.free[j]
    }

    /// Whether each of the cells `cells` is free.
    fn free_among(&self, cells: Range<usize>) -> &[bool] {
        &self.free[cells]
    }

    /// Frees or blocks cell `j`.
    pub fn set_free(&mut self, j: usize, free: bool) {
        match (self.free[j], free) {
            (false, true) => self.free_cells += 1,
            (true, false) => self.free_cells -= 1,
            _ => return,
        }
        self.free[j] = free;
    }

    /// The free cells' capacity together (their count times `h^d`).
    pub fn free_volume(&self) -> f64 {
        self.free_cells as f64 * self.cell_volume()
    }
}

/// Solves `c e^g + b e^(g / eta) = cap` for `v = e^g` by Newton's method on
/// `phi(g) = log(c e^g + b e^(g / eta)) - log cap`, increasing and convex, from the upper bound
/// `min(log(cap / c), eta log(cap / b))` (each term alone at most `cap`): the iterates
/// decrease monotonically to the root.
fn baseline_newton(cap: f64, c: f64, b: f64, eta: f64) -> f64 {
    let bound = |x: f64, scale: f64| match x > 0.0 {
        true => scale * (cap / x).ln(),
        false => f64::INFINITY,
    };
    let mut g = bound(c, 1.0).min(bound(b, eta));
    for _ in 0..NEWTON_STEPS {
        let (kc, kb) = (c * g.exp(), b * (g / eta).exp());
        let step = ((kc + kb).ln() - cap.ln()) * (kc + kb) / (kc + kb / eta);
        g -= step;
        if step.abs() < NEWTON_TOLERANCE {
            break;
        }
    }
    g.exp()
}

/// Why no plan was found.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SinkhornError {
    /// A point has no cell with capacity within the kernel's reach.
    #[error(
        "point {point} has no free transport cell within the kernel's reach \
         (epsilon too small for the transport grid, or the point is in a solid)"
    )]
    KernelVanishes { point: usize },
    /// The points' volume exceeds the capacity of all cells.
    #[error(
        "the particles' volume {volume:.6} exceeds the free volume {capacity:.6} of the \
         transport grid"
    )]
    Overfull { volume: f64, capacity: f64 },
    /// A row scaling became infinite, zero or NaN.
    #[error("the scalings left the finite range at iteration {iteration}")]
    Diverged { iteration: u32 },
}

/// The solved plan `T_pj = u_p K_pj v_j`: the scalings, what the iteration did, and every
/// point's row (its ball's cells and their kernel values) to read it by.
///
/// The cells some point reaches are numbered in grid order by *slots*; [`Self::active_cells`]
/// gives each slot's cell.
#[derive(Clone, Debug)]
pub struct Transport<const D: usize> {
    /// Row updates done.
    pub iterations: u32,
    /// The largest relative column error after the last row update.
    pub error: f64,
    /// Whether `error <= delta` (otherwise the iteration cap was reached, or see
    /// [`Self::out_of_range`]).
    pub converged: bool,
    /// Whether the iteration stopped because the next column scalings would have left
    /// [`SCALING_RANGE`]: marginals it cannot meet. The plan is the last one with exact rows
    /// (every point holds its volume), its column error `error`.
    pub out_of_range: bool,
    /// The points' volume `V_p`.
    pub volume: f64,
    /// `V_j` of a free cell.
    cell_volume: f64,
    /// The air's cost, with each slot's baseline.
    air: Air<Vec<f64>>,
    /// `u_p`, one per point, and `v_j`, one per slot.
    u: Vec<f64>,
    v: Vec<f64>,
    /// The kernel `K_pj`, which numbers the slots.
    kernel: Kernel<D>,
    /// Each slot's cell (as in the kernel; alone in a plan from [`Self::from_warm_parts`]).
    active: Vec<u32>,
}

impl<const D: usize> Transport<D> {
    /// What a warm start reads of a plan ([`Self::start_from`]): each slot's cell, the row
    /// scalings `u_p` and the column scalings `v_j`.
    pub fn warm_parts(&self) -> (&[u32], &[f64], &[f64]) {
        (&self.active, &self.u, &self.v)
    }

    /// A plan holding only [`Self::warm_parts`] (from a checkpoint), to warm-start the next
    /// solve exactly as the plan they came from would.
    pub fn from_warm_parts(active: Vec<u32>, u: Vec<f64>, v: Vec<f64>) -> Self {
        Self {
            iterations: 0,
            error: 0.0,
            converged: false,
            out_of_range: false,
            volume: 0.0,
            cell_volume: 0.0,
            air: Air::Capacity,
            u,
            v,
            kernel: Kernel::empty(),
            active,
        }
    }

    /// Solves the transport of `points`, each of volume `volume`, to `tg` with its air costed
    /// by `air`, starting from a previous plan `warm` on the same grid ([`Self::start_from`];
    /// `u = v = 1` if none), whose storage it reuses.
    pub fn solve(
        tg: &TransportGrid<D>,
        air: &AirCost,
        points: &[Vector<D>],
        volume: f64,
        s: &SinkhornSettings,
        mut warm: Option<Self>,
    ) -> Result<Self, SinkhornError> {
        let capacity = tg.free_volume();
        let total = volume * points.len() as f64;
        if total > capacity {
            return Err(SinkhornError::Overfull {
                volume: total,
                capacity,
            });
        }
        let storage = warm
            .as_mut()
            .map(|w| std::mem::replace(&mut w.kernel, Kernel::empty()));
        let kernel = Kernel::new(tg, points, s, storage.unwrap_or_else(Kernel::empty))?;
        let mut t = Self::new(tg, air, kernel, volume);
        if let Some(w) = warm {
            t.start_from(w);
        }
        let (mut next, mut relax) = (vec![], true);
        loop {
            // A cold start's `u` is 0: its first row update is exact.
            let rows = t.update_rows(relax && t.iterations > 0)?;
            // The columns follow the row scalings taken; the stopping test is on the plan
            // whose rows are exact.
            let taken = rows.relaxed.as_ref().map_or(&rows.sums, |r| &r.1);
            let (last, in_range);
            (last, (t.error, in_range)) = (
                t.error,
                t.column_update(taken, &rows.sums, &mut next, relax),
            );
            t.converged = t.error <= s.delta;
            t.out_of_range = !in_range && !t.converged;
            if t.converged || t.out_of_range || t.iterations >= s.max_iterations {
                t.u = rows.exact;
                break;
            }
            t.u = rows.relaxed.map_or(rows.exact, |(u, _)| u);
            // Past the first steps, an error that grows ends the over-relaxation: plain
            // Sinkhorn from there on, which converges from any start (Sinkhorn 1967).
            relax &= t.iterations <= RELAXED_START || t.error <= last;
            std::mem::swap(&mut t.v, &mut next);
        }
        Ok(t)
    }

    /// Starts from a previous plan's scalings: its column scalings `v_j` in the cells both
    /// reach (1 in the others); then, when its points are the first of these, in order, their
    /// row scalings `u_p` carried over (the other points' from those `v_j`) and one column
    /// update. A cell's `v_j` stays with the cell while the liquid moves through it; a
    /// point's `u_p` moves with the point, so where a cell that few kernels reach moves with
    /// the liquid (a deep cell that must be full), the carried `u_p` already hold it (our
    /// choice; Qu et al. and Levi say nothing of warm starts).
    ///
    /// Where the carried scalings would leave [`SCALING_RANGE`] at once (a plan that stopped
    /// out of range), it starts cold instead.
    fn start_from(&mut self, w: Self) {
        let mut at = 0;
        for (&j, v) in self.active.iter().zip(&mut self.v) {
            while w.active.get(at).is_some_and(|&i| i < j) {
                at += 1;
            }
            if w.active.get(at) == Some(&j) {
                *v = w.v[at];
            }
        }
        if w.u.len() > self.u.len() {
            return;
        }
        self.u = (0..self.u.len())
            .into_par_iter()
            .map(|p| w.u.get(p).copied().unwrap_or_else(|| self.row_scaling(p)))
            .collect();
        let c = self.kernel.columns(0.0, |p| self.u[p]);
        let mut next = vec![];
        match self.column_update(&c, &c, &mut next, false) {
            (_, true) => std::mem::swap(&mut self.v, &mut next),
            (_, false) => {
                self.v.fill(1.0);
                self.u.fill(0.0);
            }
        }
    }

    /// A plan on `kernel`, every scaling 1, with its slots' baselines.
    fn new(tg: &TransportGrid<D>, air: &AirCost, kernel: Kernel<D>, volume: f64) -> Self {
        let active = kernel.active().to_vec();
        let air = match air {
            Air::Capacity => Air::Capacity,
            Air::Baseline { eta, baseline } => Air::Baseline {
                eta: *eta,
                baseline: active.par_iter().map(|&j| baseline(j as usize)).collect(),
            },
        };
        Self {
            iterations: 0,
            error: f64::INFINITY,
            converged: false,
            out_of_range: false,
            volume,
            cell_volume: tg.cell_volume(),
            air,
            u: vec![0.0; kernel.points()],
            v: vec![1.0; active.len()],
            active,
            kernel,
        }
    }

    /// Point `p`'s row scaling `u_p = V_p / sum_j K_pj v_j`: its volume exact.
    fn row_scaling(&self, p: usize) -> f64 {
        self.volume / self.kernel.row_sum(p, &self.v)
    }

    /// Row update: every point's exact row scaling and, with `relax`, each over-relaxed from
    /// its current one by [`ROW_OMEGA`] (as the columns are, [`Self::overrelaxed`]), with the
    /// column sums `C_j = sum_p K_pj u_p` of both (one pass over the rows); the caller takes the
    /// scalings.
    fn update_rows(&mut self, relax: bool) -> Result<RowUpdate, SinkhornError> {
        let u = &self.u;
        let relaxed = |p: usize, exact: f64| u[p] * (exact / u[p]).powf(ROW_OMEGA);
        let rows = (self.kernel).rows_then_columns(&self.v, self.volume, relax.then_some(relaxed));
        self.iterations += 1;
        let normal = |u: &[f64]| {
            u.par_iter()
                .with_min_len(VALUE_GRAIN)
                .all(|u| u.is_normal())
        };
        match normal(&rows.exact) && rows.relaxed.as_ref().is_none_or(|r| normal(&r.0)) {
            true => Ok(rows),
            false => Err(SinkhornError::Diverged {
                iteration: self.iterations,
            }),
        }
    }

    /// The column update, every cell's marginal met, from `C_j` (per slot in `c`), into
    /// `next`; returns the largest relative column error of the current scalings with the
    /// column sums `tested` (those of exact rows) and whether the new scalings are all within
    /// [`SCALING_RANGE`] (one pass for both).
    fn column_update(
        &self,
        c: &[f64],
        tested: &[f64],
        next: &mut Vec<f64>,
        relax: bool,
    ) -> (f64, bool) {
        next.resize(self.v.len(), 0.0);
        (next
            .par_iter_mut()
            .zip(&self.v)
            .zip(c.par_iter().zip(tested))
            .enumerate())
        .with_min_len(SLOTS_PER_TASK)
        .map(|(k, ((next, &v), (&c, &tested)))| {
            let exact = self.column_scaling(k, c, v);
            *next = match relax {
                true => self.overrelaxed(v, exact),
                false => exact,
            };
            (self.column_error(k, v * tested, v), scaling_in_range(*next))
        })
        .reduce(|| (0.0, true), |(a, p), (b, q)| (a.max(b), p && q))
    }

    /// The over-relaxed column scaling `v (v* / v)^omega` from the current `v` and the exact
    /// update `v*`, `omega = 3/2` (`g <- g + omega (g* - g)` on `g = log v`; Thibault,
    /// Chizat, Dossal, Papadakis, "Overrelaxed Sinkhorn-Knopp algorithm for regularized
    /// optimal transport", Algorithms 14(5), 2021; Lehmann et al., "A note on overrelaxation
    /// in the Sinkhorn algorithm", Optim. Lett. 16, 2022, prove global convergence for
    /// `omega` in a range above 1), under the capacity form no more than 1. The value of
    /// `omega` is ours, measured with exact rows: on dam-3d at 48^3 (steps 151-160, 34.5
    /// iterations a step unrelaxed) 1.3, 1.5, 1.65 and 1.8 took 25.6, 20.4, 21.9 and 23.6
    /// (docs/benchmarks/powerpic.md); with the rows relaxed too, 1.7 took 12.3 against 3/2's
    /// 9.6 (rows at 1.85). 3/2 costs a square root, not a power.
    fn overrelaxed(&self, v: f64, exact: f64) -> f64 {
        let ratio = exact / v;
        let relaxed = v * ratio * ratio.sqrt();
        match self.air {
            Air::Capacity => relaxed.min(1.0),
            Air::Baseline { .. } => relaxed,
        }
    }

    /// The column scaling `v_j` that makes slot `k`'s column meet its marginal, given
    /// `C_j = sum_p K_pj u_p > 0` (the module doc derives it); `v` is the current one, kept
    /// where the marginal says nothing (an empty baseline and no kernel).
    fn column_scaling(&self, k: usize, c: f64, v: f64) -> f64 {
        let cap = self.cell_volume;
        match &self.air {
            Air::Capacity => (cap / c).min(1.0),
            Air::Baseline { eta, baseline } => match (baseline[k], *eta) {
                (b, _) if c == 0.0 && b == 0.0 => v,
                (b, 1.0) => cap / (c + b),
                (b, eta) => baseline_newton(cap, c, b, eta),
            },
        }
    }

    /// Slot `k`'s relative column error when its kernels fill `fill = v_j C_j` of its cell and
    /// its column scaling is `v`.
    pub fn column_error(&self, k: usize, fill: f64, v: f64) -> f64 {
        let ratio = fill / self.cell_volume;
        match &self.air {
            Air::Capacity if v < 1.0 => (ratio - 1.0).abs(),
            Air::Capacity => (ratio - 1.0).max(0.0),
            Air::Baseline { eta, baseline } => {
                let air = baseline[k] * if *eta == 1.0 { v } else { v.powf(1.0 / eta) };
                (ratio + air / self.cell_volume - 1.0).abs()
            }
        }
    }

    /// `sum_p T_pj w(p)` for every slot (e.g. `w = 1`: the volume the kernels put in each
    /// cell).
    pub fn columns<T>(&self, zero: T, w: impl Fn(usize) -> T + Sync) -> Vec<T>
    where
        T: Summand + Send + Sync,
    {
        let mut c = self.kernel.columns(zero, |p| w(p) * self.u[p]);
        c.iter_mut().zip(&self.v).for_each(|(c, &v)| *c = *c * v);
        c
    }

    /// Calls `f(k, T_pj)` for every cell of point `p`'s row (`k` its slot).
    #[inline(always)]
    pub fn for_each_in_row(&self, p: usize, mut f: impl FnMut(usize, f64)) {
        let u = self.u[p];
        (self.kernel).for_each_in_row(p, |k, kpj| f(k, u * kpj * self.v[k]));
    }

    /// `(p, f(p))` of the points `p` at the places `sorted` of the order that keeps the rows'
    /// cells in cache (the points sorted by cell), computed and given in that order; `f` may
    /// read rows with [`Self::for_each_in_row`]. The places run over `0..self.points()`, all
    /// at once or a piece at a time.
    pub fn by_rows<T: Send>(
        &self,
        sorted: Range<usize>,
        f: impl Fn(usize) -> T + Sync,
    ) -> ByRows<'_, T> {
        self.kernel.by_rows(sorted, f)
    }

    /// The points' count.
    pub fn points(&self) -> usize {
        self.kernel.points()
    }

    /// Each slot's cell: the cells with capacity within the reach of some point.
    pub fn active_cells(&self) -> &[u32] {
        &self.active
    }

    /// `v_j` of every slot.
    pub fn column_scalings(&self) -> &[f64] {
        &self.v
    }
}

#[cfg(test)]
mod tests {
    use super::kernel::cell_of;
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    const S: SinkhornSettings = SinkhornSettings {
        epsilon: 0.1,
        delta: 0.1,
        max_iterations: 10_000,
    };

    /// A test's air: the baseline of each cell from a list.
    type ListedAir = Air<Box<dyn Fn(usize) -> f64 + Sync>>;

    fn listed(eta: f64, baseline: Vec<f64>) -> ListedAir {
        Air::Baseline {
            eta,
            baseline: Box::new(move |j| baseline[j]),
        }
    }

    /// `n` random points in a box of `cells` transport cells of side 0.5, the middle cell
    /// blocked, their volumes together `fill` times the free volume; air free.
    fn instance<const D: usize>(
        cells: [usize; D],
        n: usize,
        fill: f64,
        seed: u64,
    ) -> (TransportGrid<D>, Vec<Vector<D>>, f64) {
        let grid = Grid::new(cells);
        let mut tg = TransportGrid::new(grid, 0.5);
        tg.set_free(tg.grid.num_cells() / 2, false);
        let points = random_points(&tg, n, 1.0, seed);
        let v = fill * tg.free_volume() / n as f64;
        (tg, points, v)
    }

    /// `n` random points in the free cells of `tg` below `height` times its height (axis 1).
    fn random_points<const D: usize>(
        tg: &TransportGrid<D>,
        n: usize,
        height: f64,
        seed: u64,
    ) -> Vec<Vector<D>> {
        let mut rng = StdRng::seed_from_u64(seed);
        let dims = tg.grid.dims;
        (0..n)
            .map(|_| loop {
                let x = Vector::<D>::from_fn(|k, _| {
                    let side = dims[k] as f64 * tg.h * if k == 1 { height } else { 1.0 };
                    rng.random::<f64>() * side
                });
                if tg.is_free(tg.grid.cell_index(cell_of(tg, &x))) {
                    break x;
                }
            })
            .collect()
    }

    /// A tank of `cells` transport cells of side 0.5, half full: a solid wall (the cells of
    /// axis 0 index 2, below three quarters of the height), `n` random points below half its
    /// height carrying its free volume there, the air baseline zero below 3/8 of the height,
    /// half the cell volume up to 5/8 (the surface) and the cell volume above. (A baseline
    /// that is zero in exactly the cells the points' volume fills leaves no room for the
    /// kernels' tails: those cells must be full, and the plan only tends to that as the air
    /// cells' scalings go to zero.)
    fn half_full<const D: usize>(
        cells: [usize; D],
        n: usize,
        eta: f64,
        seed: u64,
    ) -> (TransportGrid<D>, ListedAir, Vec<Vector<D>>, f64) {
        let grid = Grid::new(cells);
        let cell = 0.5f64.powi(D as i32);
        let at = |j: usize| grid.cell_coords(j);
        let wall = |j: usize| at(j)[0] == 2 && 4 * at(j)[1] < 3 * cells[1];
        let below = |j: usize| 2 * at(j)[1] < cells[1];
        let baseline = (0..grid.num_cells())
            .map(|j| match 8 * at(j)[1] {
                y if y < 3 * cells[1] => 0.0,
                y if y < 5 * cells[1] => cell / 2.0,
                _ => cell,
            })
            .collect();
        let liquid: f64 = (0..grid.num_cells())
            .filter(|&j| below(j) && !wall(j))
            .map(|_| cell)
            .sum();
        let mut tg = TransportGrid::new(grid.clone(), 0.5);
        (0..grid.num_cells()).for_each(|j| tg.set_free(j, !wall(j)));
        let points = random_points(&tg, n, 0.5, seed);
        (tg, listed(eta, baseline), points, liquid / n as f64)
    }

    /// Both marginals, recounted entry by entry through the rows and through the columns, and
    /// each column's, with the air its model gives, met to `delta`.
    fn check_marginals<const D: usize>(
        tg: &TransportGrid<D>,
        air: &AirCost,
        t: &Transport<D>,
        n: usize,
        delta: f64,
    ) {
        assert!(
            t.converged,
            "stopped at {} iterations, error {}",
            t.iterations, t.error
        );
        let cols = t.columns(0.0, |_| 1.0);
        let mut by_rows = vec![0.0; cols.len()];
        for p in 0..n {
            let mut row = 0.0;
            t.for_each_in_row(p, |k, v| {
                row += v;
                by_rows[k] += v;
            });
            assert!(
                (row / t.volume - 1.0).abs() < 1e-12,
                "row {p}: {row} for {}",
                t.volume
            );
        }
        for (k, &j) in t.active_cells().iter().enumerate() {
            let (j, v) = (j as usize, t.column_scalings()[k]);
            assert!((cols[k] - by_rows[k]).abs() <= 1e-12 * (1.0 + cols[k]));
            assert!(tg.is_free(j), "a blocked cell holds volume");
            let ratio = cols[k] / tg.cell_volume();
            match air {
                Air::Capacity => {
                    assert!(ratio <= 1.0 + delta, "cell {j} over-full: {ratio}");
                    assert!(v >= 1.0 || ratio >= 1.0 - delta, "full cell {j} at {ratio}");
                }
                Air::Baseline { eta, baseline } => {
                    let air = baseline(j) * v.powf(1.0 / eta) / tg.cell_volume();
                    let e = ratio + air - 1.0;
                    assert!(e.abs() <= delta, "cell {j}: {ratio} kernels + {air} air");
                }
            }
        }
    }

    /// Points crowded into a pocket of free cells that holds less than they do, walled off by
    /// blocked cells wider than a ball: the rows and columns cannot both be met.
    fn pocket<const D: usize>(
        cells: [usize; D],
        n: usize,
    ) -> (TransportGrid<D>, Vec<Vector<D>>, f64) {
        let mut tg = TransportGrid::new(Grid::new(cells), 0.5);
        let wall = 2..2 + (S.radius() / tg.h).ceil() as usize + 2;
        for j in 0..tg.grid.num_cells() {
            tg.set_free(j, !wall.contains(&tg.grid.cell_coords(j)[0]));
        }
        let mut rng = StdRng::seed_from_u64(D as u64);
        let points = (0..n)
            .map(|_| {
                Vector::<D>::from_fn(|k, _| {
                    rng.random::<f64>() * tg.h * if k == 0 { 2.0 } else { cells[k] as f64 }
                })
            })
            .collect();
        let volume = tg.cell_volume() / 2.0;
        (tg, points, volume)
    }

    #[test]
    fn marginals_that_cannot_be_met_stop_the_iteration_in_range_in_2d_and_3d() {
        fn check<const D: usize>(cells: [usize; D]) {
            let room = 2 * cells[1..].iter().product::<usize>();
            let (tg, pts, volume) = pocket(cells, 4 * room);
            let held = volume * pts.len() as f64;
            assert!(held > room as f64 * tg.cell_volume() && held <= tg.free_volume());
            let s = SinkhornSettings {
                max_iterations: 1_000_000,
                ..S
            };
            let t = Transport::solve(&tg, &Air::Capacity, &pts, volume, &s, None).unwrap();
            assert!(
                t.out_of_range && !t.converged,
                "{} iterations",
                t.iterations
            );
            assert!(t.iterations < s.max_iterations && t.error > s.delta);
            let (_, u, v) = t.warm_parts();
            assert!(u.iter().chain(v).all(|x| x.is_normal() && *x > 0.0));
            for p in 0..pts.len() {
                let mut row = 0.0;
                t.for_each_in_row(p, |_, t| row += t);
                assert!((row / volume - 1.0).abs() < 1e-12, "row {p}: {row}");
            }
            // A warm start from it does not carry the scalings out of range.
            let again = Transport::solve(&tg, &Air::Capacity, &pts, volume, &s, Some(t)).unwrap();
            assert!(again.out_of_range && !again.converged);
        }
        check([24, 6]);
        check([20, 4, 3]);
    }

    #[test]
    fn random_instances_meet_both_marginals_to_delta_in_2d_and_3d() {
        for seed in 0..4 {
            // Half full (a free surface) and nearly full (most cells full).
            for fill in [0.5, 0.9] {
                let (tg, pts, v) = instance([16, 12], 150, fill, seed);
                let t = Transport::solve(&tg, &Air::Capacity, &pts, v, &S, None).unwrap();
                check_marginals(&tg, &Air::Capacity, &t, pts.len(), S.delta);
                let (tg, pts, v) = instance([8, 6, 7], 300, fill, seed);
                let t = Transport::solve(&tg, &Air::Capacity, &pts, v, &S, None).unwrap();
                check_marginals(&tg, &Air::Capacity, &t, pts.len(), S.delta);
            }
        }
        // A tighter delta is met as well.
        let tight = SinkhornSettings { delta: 1e-6, ..S };
        let (tg, pts, v) = instance([16, 12], 150, 0.9, 7);
        let t = Transport::solve(&tg, &Air::Capacity, &pts, v, &tight, None).unwrap();
        check_marginals(&tg, &Air::Capacity, &t, pts.len(), 1e-6);
    }

    #[test]
    fn with_an_air_baseline_both_marginals_are_met_to_delta_in_2d_and_3d() {
        // Half full with a free surface and a solid wall, at eta = 1 (closed form) and 3
        // (Newton), to Levi's delta and to a tight one.
        for (seed, eta, delta) in [(0, 1.0, 0.1), (1, 3.0, 0.1), (2, 1.0, 1e-6), (3, 0.5, 1e-6)] {
            let s = SinkhornSettings { delta, ..S };
            let (tg, air, pts, v) = half_full([16, 12], 200, eta, seed);
            let t = Transport::solve(&tg, &air.cost(), &pts, v, &s, None).unwrap();
            check_marginals(&tg, &air.cost(), &t, pts.len(), delta);
            let (tg, air, pts, v) = half_full([8, 8, 6], 400, eta, seed);
            let t = Transport::solve(&tg, &air.cost(), &pts, v, &s, None).unwrap();
            check_marginals(&tg, &air.cost(), &t, pts.len(), delta);
        }
    }

    #[test]
    fn the_baseline_column_update_solves_its_equation() {
        // At eta = 1 the closed form; otherwise Newton meets v c + b v^(1/eta) = cap.
        for (cap, c, b, eta) in [
            (0.25, 0.3, 0.1, 2.0),
            (0.25, 1e-6, 0.25, 3.0),
            (0.125, 5.0, 0.0, 0.5),
            (0.125, 0.0, 0.1, 0.5),
            (1.0, 0.5, 0.5, 1.0 + 1e-9),
        ] {
            let v = baseline_newton(cap, c, b, eta);
            let lhs = v * c + b * v.powf(1.0 / eta);
            assert!(
                (lhs / cap - 1.0).abs() < 1e-12,
                "{cap} {c} {b} {eta}: {lhs}"
            );
        }
        let v = baseline_newton(1.0, 0.5, 0.5, 1.0 + 1e-9);
        assert!((v - 1.0).abs() < 1e-8, "{v}");
    }

    /// Solves the instance `(tg, points, v)` on `threads[0]` and on `threads[1]` threads and
    /// asserts the same plan, bit for bit (scalings, iterations, column sums); gives the
    /// kernel's chunk count.
    fn same_plan_on<const D: usize>(
        (tg, points, v): &(TransportGrid<D>, Vec<Vector<D>>, f64),
        threads: [usize; 2],
    ) -> usize {
        let s = SinkhornSettings { delta: 1e-3, ..S };
        let [a, b] = threads.map(|threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let t = Transport::solve(tg, &Air::Capacity, points, *v, &s, None).unwrap();
                let sums = t.columns(0.0, |p| p as f64);
                (t, sums)
            })
        });
        assert_eq!(
            (&a.0.v, &a.0.u, a.0.iterations),
            (&b.0.v, &b.0.u, b.0.iterations)
        );
        assert_eq!(a.1, b.1);
        a.0.kernel.chunks()
    }

    #[test]
    fn the_plan_is_the_same_whatever_the_thread_count() {
        same_plan_on(&instance([10, 8, 6], 200, 0.8, 3), [1, 2]);
    }

    /// With more chunks than a wave holds on one thread (16), and one wave for all of them on
    /// eight threads (32 a wave): the same plan, bit for bit.
    #[test]
    fn the_plan_is_the_same_whatever_the_waves_of_chunks() {
        let chunks = same_plan_on(&instance([40, 40, 40], 100_000, 0.8, 5), [1, 8]);
        assert!((17..=32).contains(&chunks), "{chunks}");
    }

    #[test]
    fn a_warm_start_from_the_same_points_converges_at_once_and_takes_new_points() {
        let s = SinkhornSettings { delta: 1e-6, ..S };
        let (tg, air, pts, v) = half_full([16, 12], 200, 1.0, 5);
        let air = air.cost();
        let cold = Transport::solve(&tg, &air, &pts, v, &s, None).unwrap();
        assert!(cold.iterations > 1, "{}", cold.iterations);
        let (iterations, scalings) = (cold.iterations, cold.v.clone());
        let warm = Transport::solve(&tg, &air, &pts, v, &s, Some(cold)).unwrap();
        check_marginals(&tg, &air, &warm, pts.len(), 1e-6);
        assert_eq!(warm.iterations, 1, "cold: {iterations}");
        let moved = (warm.v.iter().zip(&scalings)).map(|(a, b)| (a / b - 1.0).abs());
        assert!(moved.fold(0.0, f64::max) < 1e-5);
        // Two more points after the same ones, the volume shared out anew.
        let more: Vec<_> = pts.iter().chain(&pts[..2]).copied().collect();
        let v = v * pts.len() as f64 / more.len() as f64;
        let t = Transport::solve(&tg, &air, &more, v, &s, Some(warm)).unwrap();
        check_marginals(&tg, &air, &t, more.len(), 1e-6);
    }

    /// Point `x`'s row alone on `tg`: its volume, barycentre and largest entry.
    fn lone_row<const D: usize>(
        tg: &TransportGrid<D>,
        air: &AirCost,
        x: Vector<D>,
        v: f64,
    ) -> (f64, Vector<D>, f64) {
        let s = SinkhornSettings {
            delta: 1e-12,
            max_iterations: 50,
            ..S
        };
        let t = Transport::solve(tg, air, &[x], v, &s, None).unwrap();
        check_marginals(tg, air, &t, 1, 1e-10);
        let (mut mass, mut centre, mut peak) = (0.0, Vector::<D>::zeros(), 0.0f64);
        t.for_each_in_row(0, |k, v| {
            mass += v;
            centre += v * tg.center(t.active_cells()[k] as usize);
            peak = peak.max(v);
        });
        (mass, centre / mass, peak)
    }

    #[test]
    fn a_lone_point_at_a_cell_centre_gets_a_symmetric_gaussian_around_it() {
        // Far from the walls and from any full cell: the row is the normalised kernel, whose
        // barycentre is the point, and one row update is the whole solve.
        let grid = Grid::new([20, 20]);
        let tg = TransportGrid::new(grid, 0.5);
        let x = Vector::<2>::new(5.25, 4.75);
        let (mass, centre, peak) = lone_row(&tg, &Air::Capacity, x, 0.2);
        assert!((mass - 0.2).abs() < 1e-15);
        assert!((centre - x).norm() < 1e-12);
        // The peak cell holds 1 / sum_j exp(-|x - x_j|^2 / eps) of the volume, within the
        // rounding of the kernel's factors to single precision (each K_pj within 2 2^-24 of
        // its value in 2D, so the sum too; kernel.rs).
        let z: f64 = (-8i32..=8)
            .flat_map(|a| (-8i32..=8).map(move |b| (a, b)))
            .filter(|(a, b)| 0.25 * (a * a + b * b) as f64 <= S.radius().powi(2))
            .map(|(a, b)| (-0.25 * (a * a + b * b) as f64 / 0.1).exp())
            .sum();
        let rounding = 2.0 * f32::EPSILON as f64 / 2.0 + 1e-12;
        assert!(
            (peak * z / 0.2 - 1.0).abs() <= rounding,
            "{peak} vs {}",
            0.2 / z
        );
    }

    #[test]
    fn a_lone_point_in_a_half_full_region_keeps_its_volume_and_its_centre_2d_and_3d() {
        // Every cell's baseline is half its volume: the air takes half of each cell, the
        // kernel stays a symmetric Gaussian holding exactly V_p, and both marginals hold.
        fn check<const D: usize>(x: Vector<D>) {
            let grid = Grid::new([16; D]);
            let cell = 0.5f64.powi(D as i32);
            let n = grid.num_cells();
            let tg = TransportGrid::new(grid, 0.5);
            let air = listed(1.0, vec![cell / 2.0; n]);
            let (mass, centre, _) = lone_row(&tg, &air.cost(), x, 0.3 * cell);
            assert!((mass / (0.3 * cell) - 1.0).abs() < 1e-12, "{D}D: {mass}");
            assert!((centre - x).norm() < 1e-12, "{D}D: {centre:?}");
        }
        check(Vector::<2>::new(4.25, 3.75));
        check(Vector::<3>::new(4.25, 3.75, 4.25));
    }

    #[test]
    fn refuses_overfull_and_out_of_reach_points() {
        let s = SinkhornSettings {
            max_iterations: 100,
            ..S
        };
        let (tg, pts, v) = instance([6, 6], 20, 1.0, 1);
        let e = Transport::solve(&tg, &Air::Capacity, &pts, v * 1.01, &s, None).unwrap_err();
        assert!(matches!(e, SinkhornError::Overfull { .. }), "{e}");
        let tiny = SinkhornSettings { epsilon: 1e-4, ..s };
        let x = [Vector::<2>::new(0.3, 0.3)];
        let e = Transport::solve(&tg, &Air::Capacity, &x, 0.1, &tiny, None).unwrap_err();
        assert_eq!(e, SinkhornError::KernelVanishes { point: 0 });
    }
}
