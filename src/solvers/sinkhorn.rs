//! Entropy-regularised optimal transport between points of equal volume and the cells of a
//! regular grid that may be partly empty, by Sinkhorn's scaling iterations in the log domain
//! (Cuturi 2013; the partial, "capacity" form of Benamou et al. 2015, sec. 5.2).
//!
//! Points `p` (volume `V_p` each) and cells `j` (centre `x_j`, capacity `V_j`): the plan `T`
//! minimises `sum T_pj |x_p - x_j|^2 + eps sum T_pj (log T_pj - 1)` subject to
//! `sum_j T_pj = V_p` for every point and `sum_p T_pj + a_j = V_j` with a slack `a_j >= 0` (the
//! empty part of the cell). Its solution is `T_pj = exp(f_p + g_j - |x_p - x_j|^2 / eps)` with
//! `g_j <= 0`, `g_j = 0` where the cell is not full. The iterations are block-coordinate ascent
//! on the dual:
//!
//! - rows: `f_p = log V_p - LSE_j (g_j - |x_p - x_j|^2 / eps)` (every point's volume exact);
//! - columns: `g_j = min(0, log V_j - LSE_p (f_p - |x_p - x_j|^2 / eps))`,
//!
//! each log-sum-exp (LSE) taken with its maximum shifted out, so that small `eps` neither
//! underflows nor overflows. The kernel is cut where it falls below `exp(-KERNEL_CUTOFF)` of
//! its peak, so every point sees only cells within `sqrt(KERNEL_CUTOFF eps)`: the plan is
//! never a dense point x cell matrix. The iteration stops, after a row update, when every
//! column meets its marginal to a relative `delta`: `|col_j / V_j - 1|` for a full cell
//! (`g_j < 0`), `col_j / V_j - 1` above its capacity for the others.
//!
//! Every pass is a gather (per point or per cell), so results are the same whatever the
//! thread count.

use crate::grid::{Cell, Grid, Vector};
use rayon::prelude::*;

/// The kernel is cut where `|x_p - x_j|^2 / eps` exceeds this: `exp(-27.63) = 1e-12`, far
/// below the tolerances `delta` the iteration is run to.
pub const KERNEL_CUTOFF: f64 = 27.631_021_115_928_547;

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

/// The cells points are transported to: a regular grid of cells of side `h` (in the points'
/// units; cell `c` covers `[c h, (c + 1) h)`) and the capacity of each (zero: not available).
#[derive(Clone, Debug)]
pub struct TransportGrid<const D: usize> {
    pub grid: Grid<D>,
    pub h: f64,
    pub capacity: Vec<f64>,
}

impl<const D: usize> TransportGrid<D> {
    pub fn center(&self, j: usize) -> Vector<D> {
        self.grid.center(self.grid.cell_coords(j)) * self.h
    }

    /// The cell holding `x` (clamped onto the grid).
    fn cell_of(&self, x: &Vector<D>) -> Cell<D> {
        std::array::from_fn(|k| ((x[k] / self.h).max(0.0) as usize).min(self.grid.dims[k] - 1))
    }

    /// Calls `f(j, x_j)` for every cell of the box of half-width `reach` cells around cell `c`.
    #[inline]
    fn for_each_in_box(&self, c: Cell<D>, reach: usize, mut f: impl FnMut(usize, Vector<D>)) {
        let lo: Cell<D> = std::array::from_fn(|k| c[k].saturating_sub(reach));
        let hi: Cell<D> = std::array::from_fn(|k| (c[k] + reach).min(self.grid.dims[k] - 1));
        let mut at = lo;
        loop {
            let x = Vector::<D>::from_fn(|k, _| (at[k] as f64 + 0.5) * self.h);
            f(self.grid.cell_index(at), x);
            let mut k = 0;
            while k < D && at[k] == hi[k] {
                at[k] = lo[k];
                k += 1;
            }
            if k == D {
                return;
            }
            at[k] += 1;
        }
    }
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
    /// A scaling became infinite or NaN.
    #[error("the scalings left the finite range at iteration {iteration}")]
    Diverged { iteration: u32 },
}

/// A running log-sum-exp: `log sum exp(v)` over the values added, with the largest shifted out.
#[derive(Clone, Copy, Debug)]
struct LogSumExp {
    max: f64,
    sum: f64,
}

impl LogSumExp {
    const EMPTY: Self = Self {
        max: f64::NEG_INFINITY,
        sum: 0.0,
    };

    #[inline]
    fn add(&mut self, v: f64) {
        if v <= self.max {
            self.sum += (v - self.max).exp();
        } else {
            self.sum = self.sum * (self.max - v).exp() + 1.0;
            self.max = v;
        }
    }

    fn value(self) -> f64 {
        self.max + self.sum.ln()
    }
}

/// The solved plan: the log scalings and what the iteration did, with the neighbour lists
/// that let it be read row by row or column by column.
#[derive(Clone, Debug)]
pub struct Transport<const D: usize> {
    /// `f_p`, one per point.
    pub f: Vec<f64>,
    /// `g_j`, one per cell (0 for cells no point reaches).
    pub g: Vec<f64>,
    /// Row updates done.
    pub iterations: u32,
    /// The largest relative column error after the last row update.
    pub error: f64,
    /// Whether `error <= delta` (otherwise the iteration cap was reached).
    pub converged: bool,
    /// The points' volume `V_p`.
    pub volume: f64,
    /// `1 / eps`, the squared reach and the reach in cells.
    inv_eps: f64,
    radius2: f64,
    reach: usize,
    /// Points bucketed by cell: those of cell `j` are `order[start[j]..start[j + 1]]`.
    start: Vec<u32>,
    order: Vec<u32>,
    /// Cells with capacity within the reach of some point.
    active: Vec<u32>,
}

impl<const D: usize> Transport<D> {
    /// Solves the transport of `points`, each of volume `volume`, to `tg`, starting from the
    /// cells' log scalings `warm` (one per cell, e.g. a previous plan's `g`; zeros if none).
    pub fn solve(
        tg: &TransportGrid<D>,
        points: &[Vector<D>],
        volume: f64,
        s: &SinkhornSettings,
        warm: Option<Vec<f64>>,
    ) -> Result<Self, SinkhornError> {
        let capacity: f64 = tg.capacity.iter().sum();
        let total = volume * points.len() as f64;
        if total > capacity {
            return Err(SinkhornError::Overfull {
                volume: total,
                capacity,
            });
        }
        let mut t = Self::neighbourhoods(tg, points, volume, s);
        if let Some(g) = warm.filter(|g| g.len() == t.g.len()) {
            t.g = g;
        }
        let log_v = volume.ln();
        loop {
            t.update_rows(tg, points, log_v)?;
            let lse = t.column_lse(tg, points);
            t.error = t.column_error(tg, &lse);
            t.converged = t.error <= s.delta;
            if t.converged || t.iterations >= s.max_iterations {
                return Ok(t);
            }
            for (&j, l) in t.active.iter().zip(&lse) {
                let j = j as usize;
                t.g[j] = (tg.capacity[j].ln() - l).min(0.0);
            }
        }
    }

    /// Buckets the points by cell and lists the cells within their reach.
    fn neighbourhoods(
        tg: &TransportGrid<D>,
        points: &[Vector<D>],
        volume: f64,
        s: &SinkhornSettings,
    ) -> Self {
        let n = tg.grid.num_cells();
        let cells: Vec<usize> = points
            .iter()
            .map(|x| tg.grid.cell_index(tg.cell_of(x)))
            .collect();
        let mut start = vec![0u32; n + 1];
        for &c in &cells {
            start[c + 1] += 1;
        }
        for j in 0..n {
            start[j + 1] += start[j];
        }
        let mut next = start.clone();
        let mut order = vec![0u32; points.len()];
        for (p, &c) in cells.iter().enumerate() {
            order[next[c] as usize] = p as u32;
            next[c] += 1;
        }
        let radius = s.radius();
        let reach = (radius / tg.h).ceil() as usize;
        let mut reached = vec![false; n];
        for j in (0..n).filter(|&j| start[j + 1] > start[j]) {
            tg.for_each_in_box(tg.grid.cell_coords(j), reach, |k, _| reached[k] = true);
        }
        let active = (0..n)
            .filter(|&j| reached[j] && tg.capacity[j] > 0.0)
            .map(|j| j as u32)
            .collect();
        Self {
            f: vec![0.0; points.len()],
            g: vec![0.0; n],
            iterations: 0,
            error: f64::INFINITY,
            converged: false,
            volume,
            inv_eps: 1.0 / s.epsilon,
            radius2: radius * radius,
            reach,
            start,
            order,
            active,
        }
    }

    /// Calls `f(j, x_j, log K_pj + g_j)` for the cells with capacity within the reach of point
    /// `x`.
    #[inline]
    fn for_each_cell(
        &self,
        tg: &TransportGrid<D>,
        x: &Vector<D>,
        mut f: impl FnMut(usize, Vector<D>, f64),
    ) {
        tg.for_each_in_box(tg.cell_of(x), self.reach, |j, xj| {
            let d2 = (xj - x).norm_squared();
            if d2 <= self.radius2 && tg.capacity[j] > 0.0 {
                f(j, xj, self.g[j] - d2 * self.inv_eps);
            }
        });
    }

    /// Calls `f(p, log K_pj + f_p)` for the points within the reach of cell `j`.
    #[inline]
    fn for_each_point(
        &self,
        tg: &TransportGrid<D>,
        points: &[Vector<D>],
        j: usize,
        mut f: impl FnMut(usize, f64),
    ) {
        let xj = tg.center(j);
        tg.for_each_in_box(tg.grid.cell_coords(j), self.reach, |k, _| {
            for &p in &self.order[self.start[k] as usize..self.start[k + 1] as usize] {
                let p = p as usize;
                let d2 = (points[p] - xj).norm_squared();
                if d2 <= self.radius2 {
                    f(p, self.f[p] - d2 * self.inv_eps);
                }
            }
        });
    }

    /// Row update: every point's volume exact.
    fn update_rows(
        &mut self,
        tg: &TransportGrid<D>,
        points: &[Vector<D>],
        log_v: f64,
    ) -> Result<(), SinkhornError> {
        let f: Vec<Option<f64>> = points
            .par_iter()
            .map(|x| {
                let mut lse = LogSumExp::EMPTY;
                self.for_each_cell(tg, x, |_, _, v| lse.add(v));
                (lse.sum > 0.0).then(|| log_v - lse.value())
            })
            .collect();
        self.iterations += 1;
        for (p, v) in f.into_iter().enumerate() {
            match v {
                None => return Err(SinkhornError::KernelVanishes { point: p }),
                Some(v) if !v.is_finite() => {
                    return Err(SinkhornError::Diverged {
                        iteration: self.iterations,
                    })
                }
                Some(v) => self.f[p] = v,
            }
        }
        Ok(())
    }

    /// `LSE_p (f_p - |x_p - x_j|^2 / eps)` of every active cell.
    fn column_lse(&self, tg: &TransportGrid<D>, points: &[Vector<D>]) -> Vec<f64> {
        self.active
            .par_iter()
            .map(|&j| {
                let mut lse = LogSumExp::EMPTY;
                self.for_each_point(tg, points, j as usize, |_, v| lse.add(v));
                lse.value()
            })
            .collect()
    }

    /// The largest relative column error, given each active cell's column LSE.
    fn column_error(&self, tg: &TransportGrid<D>, lse: &[f64]) -> f64 {
        self.active
            .iter()
            .zip(lse)
            .map(|(&j, l)| {
                let j = j as usize;
                let ratio = (self.g[j] + l).exp() / tg.capacity[j];
                if self.g[j] < 0.0 {
                    (ratio - 1.0).abs()
                } else {
                    (ratio - 1.0).max(0.0)
                }
            })
            .fold(0.0, f64::max)
    }

    /// Calls `f(j, x_j, T_pj)` for every cell of point `p`'s row (`x_j` its centre).
    pub fn for_each_in_row(
        &self,
        tg: &TransportGrid<D>,
        points: &[Vector<D>],
        p: usize,
        mut f: impl FnMut(usize, Vector<D>, f64),
    ) {
        let fp = self.f[p];
        self.for_each_cell(tg, &points[p], |j, xj, v| f(j, xj, (fp + v).exp()));
    }

    /// Calls `f(p, T_pj)` for every point of cell `j`'s column.
    pub fn for_each_in_column(
        &self,
        tg: &TransportGrid<D>,
        points: &[Vector<D>],
        j: usize,
        mut f: impl FnMut(usize, f64),
    ) {
        let gj = self.g[j];
        self.for_each_point(tg, points, j, |p, v| f(p, (gj + v).exp()));
    }

    /// The cells with capacity within the reach of some point.
    pub fn active_cells(&self) -> impl Iterator<Item = usize> + '_ {
        self.active.iter().map(|&j| j as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// `sum_p T_pj` of every cell (zero where no point reaches), through the columns.
    fn column_sums<const D: usize>(
        t: &Transport<D>,
        tg: &TransportGrid<D>,
        points: &[Vector<D>],
    ) -> Vec<f64> {
        let mut out = vec![0.0; tg.grid.num_cells()];
        for j in t.active_cells() {
            t.for_each_in_column(tg, points, j, |_, v| out[j] += v);
        }
        out
    }

    /// `n` random points in a box of `cells` transport cells of side 0.5, the middle cell
    /// blocked, their volumes together `fill` times the free volume.
    fn instance<const D: usize>(
        cells: [usize; D],
        n: usize,
        fill: f64,
        seed: u64,
    ) -> (TransportGrid<D>, Vec<Vector<D>>, f64) {
        let h: f64 = 0.5;
        let grid = Grid::new(cells);
        let mut capacity = vec![h.powi(D as i32); grid.num_cells()];
        capacity[grid.num_cells() / 2] = 0.0;
        let tg = TransportGrid { grid, h, capacity };
        let mut rng = StdRng::seed_from_u64(seed);
        let points: Vec<Vector<D>> = (0..n)
            .map(|_| loop {
                let x = Vector::<D>::from_fn(|k, _| rng.random::<f64>() * cells[k] as f64 * h);
                if tg.capacity[tg.grid.cell_index(tg.cell_of(&x))] > 0.0 {
                    break x;
                }
            })
            .collect();
        let free: f64 = tg.capacity.iter().sum();
        (tg, points, fill * free / n as f64)
    }

    /// Both marginals, recounted entry by entry through the rows and through the columns.
    fn check_marginals<const D: usize>(
        tg: &TransportGrid<D>,
        pts: &[Vector<D>],
        t: &Transport<D>,
        delta: f64,
    ) {
        assert!(
            t.converged,
            "stopped at {} iterations, error {}",
            t.iterations, t.error
        );
        for p in 0..pts.len() {
            let mut row = 0.0;
            t.for_each_in_row(tg, pts, p, |_, _, v| row += v);
            assert!(
                (row / t.volume - 1.0).abs() < 1e-12,
                "row {p}: {row} for {}",
                t.volume
            );
        }
        let cols = column_sums(t, tg, pts);
        let mut by_rows = vec![0.0; cols.len()];
        for p in 0..pts.len() {
            t.for_each_in_row(tg, pts, p, |j, _, v| by_rows[j] += v);
        }
        for j in 0..cols.len() {
            assert!((cols[j] - by_rows[j]).abs() <= 1e-12 * (1.0 + cols[j]));
            let ratio = cols[j] / tg.capacity[j].max(f64::MIN_POSITIVE);
            assert!(ratio <= 1.0 + delta, "cell {j} over-full: {ratio}");
            if t.g[j] < 0.0 {
                assert!(ratio >= 1.0 - delta, "full cell {j} at {ratio}");
            }
            if tg.capacity[j] == 0.0 {
                assert_eq!(by_rows[j], 0.0, "a blocked cell holds volume");
            }
        }
    }

    #[test]
    fn random_instances_meet_both_marginals_to_delta_in_2d_and_3d() {
        let s = SinkhornSettings {
            epsilon: 0.1,
            delta: 0.1,
            max_iterations: 10_000,
        };
        for seed in 0..4 {
            // Half full (a free surface) and nearly full (most cells full).
            for fill in [0.5, 0.9] {
                let (tg, pts, v) = instance([16, 12], 150, fill, seed);
                let t = Transport::solve(&tg, &pts, v, &s, None).unwrap();
                check_marginals(&tg, &pts, &t, s.delta);
                let (tg, pts, v) = instance([8, 6, 7], 300, fill, seed);
                let t = Transport::solve(&tg, &pts, v, &s, None).unwrap();
                check_marginals(&tg, &pts, &t, s.delta);
            }
        }
        // A tighter delta is met as well.
        let tight = SinkhornSettings { delta: 1e-6, ..s };
        let (tg, pts, v) = instance([16, 12], 150, 0.9, 7);
        check_marginals(
            &tg,
            &pts,
            &Transport::solve(&tg, &pts, v, &tight, None).unwrap(),
            1e-6,
        );
    }

    #[test]
    fn the_plan_is_the_same_whatever_the_thread_count() {
        let s = SinkhornSettings {
            epsilon: 0.1,
            delta: 1e-3,
            max_iterations: 10_000,
        };
        let (tg, pts, v) = instance([10, 8, 6], 200, 0.8, 3);
        let solve = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| Transport::solve(&tg, &pts, v, &s, None).unwrap())
        };
        let (a, b) = (solve(1), solve(2));
        assert_eq!((a.f, a.g, a.iterations), (b.f, b.g, b.iterations));
    }

    #[test]
    fn a_lone_point_at_a_cell_centre_gets_a_symmetric_gaussian_around_it() {
        // Far from the walls and from any full cell: the row is the normalised kernel, whose
        // barycentre is the point, and one row update is the whole solve.
        let grid = Grid::new([20, 20]);
        let tg = TransportGrid {
            capacity: vec![0.25; grid.num_cells()],
            grid,
            h: 0.5,
        };
        let x = Vector::<2>::new(5.25, 4.75);
        let s = SinkhornSettings {
            epsilon: 0.1,
            delta: 1e-12,
            max_iterations: 5,
        };
        let t = Transport::solve(&tg, &[x], 0.2, &s, None).unwrap();
        assert_eq!(t.iterations, 1);
        let (mut mass, mut centre, mut peak) = (0.0, Vector::<2>::zeros(), 0.0f64);
        t.for_each_in_row(&tg, &[x], 0, |_, xj, v| {
            mass += v;
            centre += v * xj;
            peak = peak.max(v);
        });
        assert!((mass - 0.2).abs() < 1e-15);
        assert!((centre / mass - x).norm() < 1e-12);
        // The peak cell holds 1 / sum_j exp(-|x - x_j|^2 / eps) of the volume.
        let z: f64 = (-8i32..=8)
            .flat_map(|a| (-8i32..=8).map(move |b| (a, b)))
            .map(|(a, b)| (-0.25 * (a * a + b * b) as f64 / 0.1).exp())
            .sum();
        assert!((peak - 0.2 / z).abs() < 1e-12, "{peak} vs {}", 0.2 / z);
    }

    #[test]
    fn refuses_overfull_and_out_of_reach_points() {
        let s = SinkhornSettings {
            epsilon: 0.1,
            delta: 0.1,
            max_iterations: 100,
        };
        let (tg, pts, v) = instance([6, 6], 20, 1.0, 1);
        let e = Transport::solve(&tg, &pts, v * 1.01, &s, None).unwrap_err();
        assert!(matches!(e, SinkhornError::Overfull { .. }), "{e}");
        let tiny = SinkhornSettings { epsilon: 1e-4, ..s };
        let e = Transport::solve(&tg, &[Vector::<2>::new(0.3, 0.3)], 0.1, &tiny, None).unwrap_err();
        assert_eq!(e, SinkhornError::KernelVanishes { point: 0 });
    }
}
