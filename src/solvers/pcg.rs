//! Conjugate gradients with a modified incomplete Cholesky, MIC(0), preconditioner for
//! symmetric positive (semi-)definite matrices with a grid stencil: each unknown couples only
//! to its axis neighbours. This is the pressure solver of paper sec. 3 ("Solve for pressure",
//! the Poisson equation of the FLIP step); it knows nothing about fluids.
//!
//! The preconditioner follows Bridson, *Fluid Simulation for Computer Graphics* (2nd ed.,
//! sec. 5.3, Fig. 5.7), written once for any dimension: the factor of row `r` needs only the
//! rows that precede it along each axis.

use crate::grid::{max_abs, nan_max};
use crate::PAR_GRAIN;
use rayon::prelude::*;
use std::borrow::Cow;

use super::NONE;

/// A sparse symmetric matrix whose rows are grid cells in ascending linear order and whose
/// off-diagonal entries connect a row to its neighbour one step up (`plus`) or down (`minus`)
/// each axis.
#[derive(Clone, Debug, Default)]
pub struct StencilMatrix<const D: usize> {
    pub diag: Vec<f64>,
    /// Row of the `+axis` neighbour, or [`NONE`].
    pub plus: Vec<[u32; D]>,
    /// Row of the `-axis` neighbour, or [`NONE`].
    pub minus: Vec<[u32; D]>,
    /// Matrix entry between a row and its `+axis` neighbour (0 where there is none).
    pub off_plus: Vec<[f64; D]>,
}

impl<const D: usize> StencilMatrix<D> {
    pub fn len(&self) -> usize {
        self.diag.len()
    }

    pub fn is_empty(&self) -> bool {
        self.diag.is_empty()
    }

    /// The entry between row `r` and its `-axis` neighbour `m` (stored on `m`).
    #[inline]
    fn off_minus(&self, r: usize, axis: usize) -> f64 {
        let m = self.minus[r][axis];
        if m == NONE {
            0.0
        } else {
            self.off_plus[m as usize][axis]
        }
    }

    /// `(A x)_r`.
    #[inline]
    pub fn row(&self, r: usize, x: &[f64]) -> f64 {
        let mut s = self.diag[r] * x[r];
        for a in 0..D {
            let p = self.plus[r][a];
            if p != NONE {
                s += self.off_plus[r][a] * x[p as usize];
            }
            let m = self.minus[r][a];
            if m != NONE {
                s += self.off_minus(r, a) * x[m as usize];
            }
        }
        s
    }

    /// `out = A x`.
    pub fn apply(&self, x: &[f64], out: &mut [f64]) {
        out.par_iter_mut()
            .with_min_len(PAR_GRAIN)
            .enumerate()
            .for_each(|(r, o)| *o = self.row(r, x));
    }
}

/// Which preconditioner CG runs with (scene key `simulation.pressure_preconditioner`; the
/// command line's `--pressure` takes the same names, `crate::cmd::cli`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preconditioner {
    /// [`Preconditioner::Multigrid`] from [`Preconditioner::AUTO_ROWS`] rows,
    /// [`Preconditioner::Mic0`] below ([`Preconditioner::for_size`]).
    #[default]
    Auto,
    /// MIC(0), modified incomplete Cholesky: cheap iterations; sequential triangular solves; an
    /// iteration count that grows with the grid.
    Mic0,
    /// The geometric multigrid V-cycle of [`crate::solvers::multigrid`] (McAdams et al. 2010):
    /// heavier, parallel iterations, their count nearly independent of the grid.
    Multigrid,
}

impl Preconditioner {
    /// The fewest rows for which [`Preconditioner::Auto`] takes multigrid, in 2D and in 3D,
    /// whatever part of the grid they fill: measured 2026-11-26, multigrid's pressure stage
    /// is 0.51-0.59x MIC(0)'s on dam-2d at 256^2 (11,880 rows) and 0.74-0.93x on dam-3d at
    /// 128^3 (115 k rows filling 5.5% of the grid), 1.0-1.08x at 100^3 (54 k).
    pub const AUTO_ROWS: [usize; 2] = [10_000, 100_000];

    /// The preconditioner a solve of `rows` rows on a `dim`-dimensional grid runs with:
    /// [`Preconditioner::Auto`] resolved by [`Preconditioner::AUTO_ROWS`], the others as they
    /// are.
    pub fn for_size(self, dim: usize, rows: usize) -> Preconditioner {
        match self {
            Preconditioner::Auto if rows >= Self::AUTO_ROWS[dim.clamp(2, 3) - 2] => {
                Preconditioner::Multigrid
            }
            Preconditioner::Auto => Preconditioner::Mic0,
            p => p,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Preconditioner::Auto => "auto",
            Preconditioner::Mic0 => "mic0",
            Preconditioner::Multigrid => "multigrid",
        }
    }
}

/// PCG settings.
#[derive(Clone, Copy, Debug)]
pub struct PcgSettings {
    /// Stop when `max|b - A x| <= tolerance * max|b|` (max-norm, relative).
    pub tolerance: f64,
    pub max_iterations: usize,
    /// MIC(0) modification parameter tau (Bridson: 0.97).
    pub tau: f64,
    /// MIC(0) safety cut-off sigma (Bridson: 0.25).
    pub sigma: f64,
    /// The preconditioner a caller that knows the grid builds
    /// ([`crate::stages::pressure::Poisson::solve`], which resolves [`Preconditioner::Auto`]
    /// by the system's size); [`solve`] has only the matrix and takes MIC(0).
    pub preconditioner: Preconditioner,
}

impl Default for PcgSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-9,
            max_iterations: 2000,
            tau: 0.97,
            sigma: 0.25,
            preconditioner: Preconditioner::Auto,
        }
    }
}

/// A system as CG sees it, in one row order: its symmetric matrix `A` and a symmetric
/// positive definite preconditioner `M^-1`.
pub trait Preconditioned {
    /// `out = A x`; returns `x . out` (CG's `s . A s`, in the same pass), summed in the
    /// fixed blocks of CG's other dot products ([`apply_dot`]).
    fn apply_dot(&self, x: &[f64], out: &mut [f64]) -> f64;

    /// `z = M^-1 r`.
    fn precondition(&mut self, r: &[f64], z: &mut [f64]);
}

/// MIC(0) of a matrix: the matrix and its factor.
pub struct Mic0<'a, const D: usize> {
    a: &'a StencilMatrix<D>,
    factor: Vec<f64>,
}

impl<'a, const D: usize> Mic0<'a, D> {
    pub fn new(a: &'a StencilMatrix<D>, settings: &PcgSettings) -> Self {
        let factor = mic0_factor(a, settings);
        Mic0 { a, factor }
    }
}

impl<const D: usize> Preconditioned for Mic0<'_, D> {
    fn apply_dot(&self, x: &[f64], out: &mut [f64]) -> f64 {
        apply_dot(x, out, |r| self.a.row(r, x))
    }

    fn precondition(&mut self, r: &[f64], z: &mut [f64]) {
        mic0_apply(self.a, &self.factor, r, z);
    }
}

/// What a solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PcgStats {
    pub iterations: usize,
    /// Final `max|b - A x|`.
    pub residual: f64,
    pub converged: bool,
}

/// The MIC(0) factor: one inverse square root of the modified pivot per row.
fn mic0_factor<const D: usize>(a: &StencilMatrix<D>, s: &PcgSettings) -> Vec<f64> {
    let n = a.len();
    let mut precon = vec![0.0; n];
    for r in 0..n {
        let mut e = a.diag[r];
        for ax in 0..D {
            let m = a.minus[r][ax];
            if m == NONE {
                continue;
            }
            let m = m as usize;
            let am = a.off_plus[m][ax];
            e -= (am * precon[m]).powi(2);
            let others: f64 = (0..D).filter(|&b| b != ax).map(|b| a.off_plus[m][b]).sum();
            e -= s.tau * am * others * precon[m] * precon[m];
        }
        if e < s.sigma * a.diag[r] {
            e = a.diag[r];
        }
        precon[r] = if e > 0.0 { 1.0 / e.sqrt() } else { 0.0 };
    }
    precon
}

/// `z = M^-1 r` with the MIC(0) factor (a forward then a backward triangular sweep).
fn mic0_apply<const D: usize>(a: &StencilMatrix<D>, precon: &[f64], r: &[f64], z: &mut [f64]) {
    let n = a.len();
    // Forward: L q = r.
    for i in 0..n {
        let mut t = r[i];
        for ax in 0..D {
            let m = a.minus[i][ax];
            if m != NONE {
                let m = m as usize;
                t -= a.off_plus[m][ax] * precon[m] * z[m];
            }
        }
        z[i] = t * precon[i];
    }
    // Backward: L^T z = q.
    for i in (0..n).rev() {
        let mut t = z[i];
        for ax in 0..D {
            let p = a.plus[i][ax];
            if p != NONE {
                t -= a.off_plus[i][ax] * precon[i] * z[p as usize];
            }
        }
        z[i] = t * precon[i];
    }
}

/// The block of [`dot`]'s fixed partial sums.
const BLOCK: usize = 4096;

/// Dot product summed in fixed blocks, so the result is bit-identical whatever the thread
/// count or scheduling (determinism, DESIGN "Units and spaces").
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let partial: Vec<f64> = a
        .par_chunks(BLOCK)
        .zip(b.par_chunks(BLOCK))
        .with_min_len(PAR_GRAIN / BLOCK)
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| p * q).sum())
        .collect();
    partial.iter().sum()
}

/// `out[i] = row(i)` for every row, returning `x . out` summed in the same fixed blocks as
/// `dot`: one pass for a matrix product and CG's dot product with it.
pub fn apply_dot(x: &[f64], out: &mut [f64], row: impl Fn(usize) -> f64 + Sync) -> f64 {
    let partial: Vec<f64> = (out.par_chunks_mut(BLOCK).enumerate())
        .with_min_len(PAR_GRAIN / BLOCK)
        .map(|(k, o)| {
            let first = k * BLOCK;
            let mut sum = 0.0;
            for (j, o) in o.iter_mut().enumerate() {
                *o = row(first + j);
                sum += x[first + j] * *o;
            }
            sum
        })
        .collect();
    partial.iter().sum()
}

/// `x += alpha s` and `r -= alpha a_s` in one pass; returns the new `max|r|` (NaN if any
/// entry is).
fn step(alpha: f64, s: &[f64], a_s: &[f64], x: &mut [f64], r: &mut [f64]) -> f64 {
    (x.par_chunks_mut(BLOCK).zip(r.par_chunks_mut(BLOCK)))
        .zip(s.par_chunks(BLOCK).zip(a_s.par_chunks(BLOCK)))
        .with_min_len(PAR_GRAIN / BLOCK)
        .map(|((x, r), (s, a_s))| {
            let mut res = 0.0;
            for j in 0..x.len() {
                x[j] += alpha * s[j];
                r[j] -= alpha * a_s[j];
                res = nan_max(res, r[j].abs());
            }
            res
        })
        .reduce(|| 0.0, nan_max)
}

/// The residual `b - A x` CG starts from: `b` itself, borrowed, for `x = 0` (a cold start:
/// bit for bit the residual of a solve from zero), else computed with the row product `row`
/// of `A`.
pub fn start_residual<'b>(
    b: &'b [f64],
    x: &[f64],
    row: impl Fn(usize) -> f64 + Sync,
) -> Cow<'b, [f64]> {
    if x.par_iter().all(|&v| v == 0.0) {
        return Cow::Borrowed(b);
    }
    (b.par_iter().with_min_len(PAR_GRAIN).enumerate())
        .map(|(i, &bi)| bi - row(i))
        .collect::<Vec<f64>>()
        .into()
}

/// What a solve reports when it needs no iteration: the start's residual `r` (`b - A x`,
/// [`start_residual`]) is within the tolerance of `max|b|` already, or the system is empty
/// (converged), or `r` is not finite (not converged, with the non-finite residual). `None`
/// when CG has to iterate.
pub fn settled(b: &[f64], r: &[f64], settings: &PcgSettings) -> Option<PcgStats> {
    let res = max_abs(r);
    let converged = res <= settings.tolerance * max_abs(b) || b.is_empty();
    (converged || !res.is_finite()).then_some(PcgStats {
        iterations: 0,
        residual: res,
        converged: converged && res.is_finite(),
    })
}

/// Solves `A x = b` by MIC(0)-PCG from the guess `x` holds (zeros for a cold start); `x`
/// receives the solution. The factor is built only if CG has to iterate ([`settled`]).
pub fn solve<const D: usize>(
    a: &StencilMatrix<D>,
    b: &[f64],
    x: &mut [f64],
    settings: &PcgSettings,
) -> PcgStats {
    assert_eq!(a.len(), b.len());
    let r = start_residual(b, x, |i| a.row(i, x));
    if let Some(stats) = settled(b, &r, settings) {
        return stats;
    }
    solve_with(&mut Mic0::new(a, settings), b, x, r.into_owned(), settings)
}

/// Solves `A x = b` by PCG on `system` from the guess `x` holds, whose residual `b - A x` is
/// `r` ([`start_residual`]), which the caller found not [`settled`] (before building the
/// preconditioner); `x` receives the solution. It stops when
/// `max|b - A x| <= tolerance max|b|` (the recursively updated residual), so a start near the
/// solution saves iterations but not accuracy. CG needs `M^-1` symmetric positive definite.
pub fn solve_with<P: Preconditioned>(
    system: &mut P,
    b: &[f64],
    x: &mut [f64],
    mut r: Vec<f64>,
    settings: &PcgSettings,
) -> PcgStats {
    let n = b.len();
    assert_eq!((x.len(), r.len()), (n, n));
    let target = settings.tolerance * max_abs(b);
    let mut res = max_abs(&r);
    let mut z = vec![0.0; n];
    system.precondition(&r, &mut z);
    let mut s = z.clone();
    let mut sigma = dot(&z, &r);
    let mut az = vec![0.0; n];
    for it in 1..=settings.max_iterations {
        let denom = system.apply_dot(&s, &mut az);
        // Not positive, or NaN: the system is not positive definite (or not finite).
        if denom <= 0.0 || denom.is_nan() {
            return PcgStats {
                iterations: it,
                residual: res,
                converged: false,
            };
        }
        let alpha = sigma / denom;
        res = step(alpha, &s, &az, x, &mut r);
        if res <= target {
            return PcgStats {
                iterations: it,
                residual: res,
                converged: true,
            };
        }
        system.precondition(&r, &mut z);
        let sigma_new = dot(&z, &r);
        let beta = sigma_new / sigma;
        sigma = sigma_new;
        s.par_iter_mut()
            .with_min_len(PAR_GRAIN)
            .zip(&z)
            .for_each(|(si, zi)| *si = zi + beta * *si);
    }
    PcgStats {
        iterations: settings.max_iterations,
        residual: res,
        converged: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use rand::{Rng, SeedableRng};

    /// The 5/7-point Dirichlet Laplacian on the cells of `grid` for which `active` holds;
    /// inactive cells and the outside are p = 0.
    fn laplacian<const D: usize>(grid: &Grid<D>, active: &[bool]) -> StencilMatrix<D> {
        let mut row = vec![NONE; grid.num_cells()];
        let mut n = 0;
        for (c, r) in row.iter_mut().enumerate() {
            if active[c] {
                *r = n;
                n += 1;
            }
        }
        let mut m = StencilMatrix::<D>::default();
        for c in (0..grid.num_cells()).filter(|&c| active[c]) {
            let cc = grid.cell_coords(c);
            let mut plus = [NONE; D];
            let mut minus = [NONE; D];
            let mut off = [0.0; D];
            for a in 0..D {
                if let Some(p) = grid.neighbor(cc, a, 1) {
                    plus[a] = row[grid.cell_index(p)];
                    if plus[a] != NONE {
                        off[a] = -1.0;
                    }
                }
                if let Some(q) = grid.neighbor(cc, a, -1) {
                    minus[a] = row[grid.cell_index(q)];
                }
            }
            m.diag.push(2.0 * D as f64);
            m.plus.push(plus);
            m.minus.push(minus);
            m.off_plus.push(off);
        }
        m
    }

    fn manufactured<const D: usize>(dims: [usize; D], seed: u64) {
        let grid = Grid::new(dims);
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let active: Vec<bool> = (0..grid.num_cells())
            .map(|_| rng.random::<f64>() < 0.8)
            .collect();
        let a = laplacian(&grid, &active);
        let exact: Vec<f64> = (0..a.len()).map(|_| rng.random::<f64>() - 0.5).collect();
        let mut b = vec![0.0; a.len()];
        a.apply(&exact, &mut b);
        let mut x = vec![0.0; a.len()];
        let settings = PcgSettings {
            tolerance: 1e-12,
            ..Default::default()
        };
        let stats = solve(&a, &b, &mut x, &settings);
        assert!(stats.converged, "{stats:?}");
        // The reported residual is the true one, and within the tolerance.
        let mut ax = vec![0.0; a.len()];
        a.apply(&x, &mut ax);
        let true_res = b
            .iter()
            .zip(&ax)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        let bmax = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(
            true_res <= 1.01 * 1e-12 * bmax + 1e-15,
            "{true_res} vs {bmax}"
        );
        let err = x
            .iter()
            .zip(&exact)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-8, "error {err}");
    }

    #[test]
    fn solves_manufactured_poisson_2d() {
        manufactured([40, 30], 1);
    }

    #[test]
    fn solves_manufactured_poisson_3d() {
        manufactured([16, 12, 14], 2);
    }

    #[test]
    fn auto_takes_multigrid_from_the_size_rule_on_and_leaves_the_others() {
        use Preconditioner::*;
        for (dim, rows) in [
            (2, Preconditioner::AUTO_ROWS[0]),
            (3, Preconditioner::AUTO_ROWS[1]),
        ] {
            assert_eq!(Auto.for_size(dim, rows - 1), Mic0);
            assert_eq!(Auto.for_size(dim, rows), Multigrid);
            for p in [Mic0, Multigrid] {
                assert_eq!(p.for_size(dim, 1), p);
                assert_eq!(p.for_size(dim, 10 * rows), p);
            }
        }
        assert!(Preconditioner::AUTO_ROWS[0] < Preconditioner::AUTO_ROWS[1]);
    }

    #[test]
    fn mic0_beats_plain_iteration_count() {
        // The preconditioner must pay: far fewer iterations than the unknowns' grid diameter
        // squared that plain CG's condition number would suggest.
        let grid = Grid::new([64, 64]);
        let a = laplacian(&grid, &vec![true; grid.num_cells()]);
        let b = vec![1.0; a.len()];
        let mut x = vec![0.0; a.len()];
        let stats = solve(&a, &b, &mut x, &PcgSettings::default());
        assert!(stats.converged);
        assert!(stats.iterations < 64, "{} iterations", stats.iterations);
    }

    #[test]
    fn a_nan_right_hand_side_is_not_converged_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D]) {
            let grid = Grid::new(dims);
            let a = laplacian(&grid, &vec![true; grid.num_cells()]);
            let mut b = vec![0.0; a.len()];
            b[a.len() / 2] = f64::NAN;
            let mut x = vec![0.0; a.len()];
            let stats = solve(&a, &b, &mut x, &PcgSettings::default());
            assert!(!stats.converged && stats.residual.is_nan(), "{stats:?}");
        }
        check([8, 8]);
        check([6, 6, 6]);
    }
}
