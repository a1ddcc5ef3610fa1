//! The kernel matrix `K_pj = e^(-|x_p - x_j|^2 / eps)` of a solve, cut where
//! `|x_p - x_j|^2 / eps` exceeds [`KERNEL_CUTOFF`](super::KERNEL_CUTOFF) and at blocked cells, in factored form: what
//! the iterations stream is a point's position and its `d (2 r + 1)` per-axis factors
//! `e^(-(x_p,k - x_j,k)^2 / eps)`, not a list of its cells and their kernel values.
//!
//! **Why factored.** A point's ball reaches about 150 transport cells in 3D at the defaults
//! (`eps = 0.1`, a grid twice as fine as the simulation's), and each Sinkhorn iteration reads
//! every row twice (the row update, then the column sums). Listed as a `u32` slot and an `f64`
//! value per cell, that is 1.8 kB per point and pass, and the iterations are bound by memory
//! bandwidth (issue 73). Factored, a point's row is its 27 factors and its runs: each line of
//! cells along axis 0 that its ball reaches, cut at blocked cells, as the slot of its first
//! cell, where the run starts in the box and how long it is, and which line of the box it is
//! (8 bytes; about 40 runs in 3D at the defaults). Each `K_pj` is rebuilt as the product of
//! its factors, which costs a multiplication; the points are visited sorted by cell, so the
//! column scalings `v_j` that neighbouring points read stay in cache.
//!
//! **The same numbers as a listed row.** A cell's `K_pj` is the product of the factors in the
//! same order (the outer axes' first, then axis 0), the ball test is on the same sum of
//! per-axis squares, and the cells are visited in grid order: every row sum and every column
//! sum is computed with the same operations in the same order as from a list of the row.
//!
//! **Factors in single precision (ours).** The factors are stored as `f32` and multiplied in
//! `f64`: each is within `2^-24` of its value relative to it, so a `K_pj` within about
//! `d 2^-24` (`2e-7` in 3D), far inside the marginal tolerance `delta = 0.1` the solve stops
//! at; half the factors' bytes (a point's row 108 bytes lighter in 3D at the defaults), which
//! the iterations stream and the step holds. The scalings, sums and the plan stay `f64`, and a
//! row update still makes every row sum exactly its volume for the kernel as stored. Every
//! factor a `K_pj` uses is at least `e^-KERNEL_CUTOFF` (`1e-12`), a normal `f32` (the box's
//! corners outside the ball may round to zero or a subnormal; no `K_pj` reads them).
//!
//! **Slots.** The cells some point's ball reaches are the *slots*, numbered in grid order, so
//! the free cells of a run have consecutive slots. To find them, the cells near the points
//! ([`Active::around_spans`], the cubes of side `2 ceil(r / h) + 1` around their cells) are
//! numbered densely, a line of cells along axis 0 at a time, while the kernel is built.

mod lanes;

pub use lanes::Summand;

use super::{SinkhornError, SinkhornSettings, TransportGrid, VALUE_GRAIN};
use crate::grid::active::{line_spans, Active, CellNumbers};
use crate::grid::lanes::cpu_has_lanes;
use crate::grid::{strides, Vector};
use crate::solvers::NONE;
use rayon::prelude::*;
use std::iter::{Map, Zip};
use std::ops::{AddAssign, Mul, Range};
use std::sync::atomic::{AtomicBool, Ordering};
use std::{slice, vec};

/// Points per chunk of the column sums: a `1 / MIN_CHUNKS` share of the points, within
/// these bounds. It depends on the point count only, so that the summation order does not
/// depend on the thread count; it is large enough in 3D that the chunks' windows of cells
/// overlap little, and small enough that a 2D tank of a few thousand points is cut into
/// chunks for every thread.
const CHUNK_POINTS: Range<usize> = 256..4096;
const MIN_CHUNKS: usize = 16;

/// Points per task of the row sums, of the factors and of the runs' listing (small enough
/// that a 2D tank of a few thousand points is shared by every thread).
const ROW_GRAIN: usize = 256;

/// Slots per block when the chunks' column sums are added.
const SLOT_BLOCK: usize = 4096;

/// The kernel matrix of a solve (see the module doc).
#[derive(Clone, Debug)]
pub(super) struct Kernel<const D: usize> {
    /// Factors per axis and point: the side `2 r + 1` of a point's box.
    side: usize,
    /// The points sorted by the cell holding them (stably), and each point's place there.
    order: Vec<u32>,
    rank: Vec<u32>,
    /// The points' factors in sorted order, in single precision (see the module doc): point
    /// `order[i]`'s factor along axis `k` at the `a`-th cell of its box is
    /// `factor[(i D + k) side + a]`.
    factor: Vec<f32>,
    /// The points' runs in sorted order, [`ROW_GRAIN`] points to a piece.
    runs: Vec<Runs>,
    /// Each slot's cell, in grid order.
    active: Vec<u32>,
    /// The chunks of the column sums: sorted points `points`, whose cells are the slots
    /// `window`.
    chunks: Vec<Chunk>,
}

#[derive(Clone, Debug)]
struct Chunk {
    points: Range<usize>,
    window: Range<usize>,
}

/// What [`Kernel::by_rows`] gives: `(p, f(p))` in the sorted order.
pub type ByRows<'a, T> = Zip<Map<slice::Iter<'a, u32>, fn(&u32) -> usize>, vec::IntoIter<T>>;

/// What [`Kernel::rows_then_columns`] gives: each point's exact row scaling and their column
/// sums, and, when the rows are relaxed, the scalings taken and their column sums.
pub(super) struct RowUpdate {
    pub exact: Vec<f64>,
    pub sums: Vec<f64>,
    pub relaxed: Option<(Vec<f64>, Vec<f64>)>,
}

/// A run of a point's row: free cells along axis 0 whose slots are `slot..slot + len`, the
/// cells `start..start + len` of the point's box along that axis, on the line of the box at
/// `at` along the outer axes 1, 2.
#[derive(Clone, Copy, Debug)]
struct Run {
    slot: u32,
    start: u8,
    len: u8,
    at: [u8; 2],
}

impl Run {
    /// The slot after the run's last.
    fn end(&self) -> usize {
        self.slot as usize + self.len as usize
    }
}

/// The runs of [`ROW_GRAIN`] consecutive sorted points: the `i`-th one's are
/// `run[first[i]..first[i + 1]]`.
#[derive(Clone, Debug, Default)]
struct Runs {
    first: Vec<u32>,
    run: Vec<Run>,
}

impl<const D: usize> Kernel<D> {
    /// No kernel: a plan that only carries scalings to warm-start the next solve.
    pub(super) fn empty() -> Self {
        Self {
            side: 0,
            order: vec![],
            rank: vec![],
            factor: vec![],
            runs: vec![],
            active: vec![],
            chunks: vec![],
        }
    }

    /// The kernel of `points` on `tg` (reusing the storage of `reuse`). A point with no free
    /// cell in its ball is refused ([`SinkhornError::KernelVanishes`], the first one).
    ///
    /// One walk over the balls: each piece of sorted points writes its factors and lists its
    /// runs with the near cells' numbers, marking the cells it reaches; the reached cells are
    /// then numbered as slots, and the runs renamed to them.
    pub(super) fn new(
        tg: &TransportGrid<D>,
        points: &[Vector<D>],
        s: &SinkhornSettings,
        reuse: Self,
    ) -> Result<Self, SinkhornError> {
        const { assert!(D <= 3, "a run names its line by at most two outer axes") };
        let ball = Ball::new(tg, points, s);
        assert!(
            ball.side() < 256,
            "a run's place in its box is a byte: epsilon / h^2 too large"
        );
        let order = sorted_by_cell(tg, points);
        let mut rank = vec![0; points.len()];
        (order.iter().enumerate()).for_each(|(i, &p)| rank[p as usize] = i as u32);
        let x: Vec<Vector<D>> = order.par_iter().map(|&p| points[p as usize]).collect();
        let (side, mut factor, mut runs) = (ball.side(), reuse.factor, reuse.runs);
        factor.resize(points.len() * D * side, 0.0);
        runs.resize_with(x.len().div_ceil(ROW_GRAIN), Runs::default);
        let reached: Vec<AtomicBool> = (0..ball.near.len()).map(|_| false.into()).collect();
        (factor
            .par_chunks_mut(ROW_GRAIN * D * side)
            .zip(&mut runs)
            .enumerate())
        .for_each(|(c, (f, r))| {
            let x = &x[c * ROW_GRAIN..(c * ROW_GRAIN + ROW_GRAIN).min(x.len())];
            ball.walk(x, s.epsilon, f, r, &reached)
        });
        let mut k = Self {
            side,
            order,
            rank,
            factor,
            runs,
            active: vec![],
            chunks: vec![],
        };
        let empty = (0..x.len())
            .into_par_iter()
            .filter(|&i| k.runs_at(i).0.is_empty());
        if let Some(p) = empty.map(|i| k.order[i]).min() {
            return Err(SinkhornError::KernelVanishes { point: p as usize });
        }
        k.number_slots(&ball, &reached);
        Ok(k)
    }

    /// The factors of the point at sorted place `i`.
    #[inline]
    fn factors_at(&self, i: usize) -> &[f32] {
        &self.factor[i * D * self.side..(i + 1) * D * self.side]
    }

    /// Numbers the `reached` near cells as slots in grid order, renames the runs' first cells
    /// from near numbers to slots, and cuts the sorted points into the chunks of the column
    /// sums with their windows of slots.
    fn number_slots(&mut self, ball: &Ball<D>, reached: &[AtomicBool]) {
        let mut slot = vec![NONE; ball.near.len()];
        for (near, cell) in ball.near.cells().enumerate() {
            if reached[near].load(Ordering::Relaxed) {
                slot[near] = self.active.len() as u32;
                self.active.push(cell as u32);
            }
        }
        (self.runs.par_iter_mut().flat_map(|r| &mut r.run))
            .for_each(|run| run.slot = slot[run.slot as usize]);
        let n = self.order.len();
        let size = (n / MIN_CHUNKS).clamp(CHUNK_POINTS.start, CHUNK_POINTS.end);
        self.chunks = (0..n.div_ceil(size))
            .into_par_iter()
            .map(|c| {
                let points = c * size..(c * size + size).min(n);
                let rows = points.clone().map(|i| self.runs_at(i).0);
                let lo = rows
                    .clone()
                    .map(|r| r[0].slot)
                    .min()
                    .expect("a chunk has points");
                let end = rows.map(|r| r[r.len() - 1].end()).max();
                Chunk {
                    points,
                    window: lo as usize..end.expect("a chunk has points"),
                }
            })
            .collect();
    }

    /// Each slot's cell: the free cells within the reach of some point, in grid order.
    pub(super) fn active(&self) -> &[u32] {
        &self.active
    }

    /// The chunks of the column sums' count.
    #[cfg(test)]
    pub(super) fn chunks(&self) -> usize {
        self.chunks.len()
    }

    /// The points' count.
    pub(super) fn points(&self) -> usize {
        self.order.len()
    }

    /// The runs of the point at sorted place `i`, with its factors.
    #[inline]
    fn runs_at(&self, i: usize) -> (&[Run], &[f32]) {
        let r = &self.runs[i / ROW_GRAIN];
        let (a, b) = (r.first[i % ROW_GRAIN], r.first[i % ROW_GRAIN + 1]);
        (&r.run[a as usize..b as usize], self.factors_at(i))
    }

    /// A run's `K_pj` but for the factor along axis 0: the product of the outer axes' factors,
    /// the last axis first.
    #[inline]
    fn outer(&self, run: &Run, factor: &[f32]) -> f64 {
        let mut kernel = 1.0;
        for k in (1..D).rev() {
            kernel *= factor[k * self.side + run.at[k - 1] as usize] as f64;
        }
        kernel
    }

    /// Calls `f(k, K_pj)` for every cell of point `p`'s row, `k` its slot, in grid order.
    #[inline(always)]
    pub(super) fn for_each_in_row(&self, p: usize, mut f: impl FnMut(usize, f64)) {
        let (runs, factor) = self.runs_at(self.rank[p] as usize);
        for run in runs {
            let kernel = self.outer(run, factor);
            let fx = &factor[run.start as usize..][..run.len as usize];
            for (k, &fx) in (run.slot as usize..).zip(fx) {
                f(k, kernel * fx as f64);
            }
        }
    }

    /// `(p, f(p))` of the points `p` at the sorted places `sorted`, in that order, so that the
    /// rows that follow one another read neighbouring slots (a walk by point would jump across
    /// the grid from row to row). Not put back in the points' order: that would hold a second
    /// copy of the values.
    pub(super) fn by_rows<T: Send>(
        &self,
        sorted: Range<usize>,
        f: impl Fn(usize) -> T + Sync,
    ) -> ByRows<'_, T> {
        let order = &self.order[sorted];
        let values: Vec<T> = (order.par_iter())
            .with_min_len(ROW_GRAIN)
            .map(|&p| f(p as usize))
            .collect();
        let point: fn(&u32) -> usize = |&p| p as usize;
        order.iter().map(point).zip(values)
    }

    /// Values given in the sorted order, `sorted`, by point.
    fn by_point<T: Copy + Send + Sync>(&self, sorted: &[T]) -> Vec<T> {
        (self.rank.par_iter().with_min_len(VALUE_GRAIN))
            .map(|&i| sorted[i as usize])
            .collect()
    }

    /// `sum_j K_pj v_j` of point `p`.
    pub(super) fn row_sum(&self, p: usize, v: &[f64]) -> f64 {
        self.row_sum_at(self.rank[p] as usize, v)
    }

    /// `sum_j K_pj v_j` of the point at sorted place `i`.
    #[inline]
    fn row_sum_at(&self, i: usize, v: &[f64]) -> f64 {
        let (runs, factor) = self.runs_at(i);
        let mut sum = 0.0;
        for run in runs {
            let kernel = self.outer(run, factor);
            let fx = &factor[run.start as usize..][..run.len as usize];
            let v = &v[run.slot as usize..][..run.len as usize];
            for (&fx, v) in fx.iter().zip(v) {
                sum += kernel * fx as f64 * v;
            }
        }
        sum
    }

    /// `sum_p K_pj w(p)` for every slot: each chunk of sorted points scatters into its
    /// window, and the windows are added in chunk order (the same sums whatever the thread
    /// count).
    pub(super) fn columns<T>(&self, zero: T, w: impl Fn(usize) -> T + Sync) -> Vec<T>
    where
        T: Summand + Send + Sync,
    {
        self.columns_in(zero, w, cpu_has_lanes())
    }

    /// [`Self::columns`], four cells at a time with `lanes` (AVX2, [`lanes`]: the same bits).
    fn columns_in<T>(&self, zero: T, w: impl Fn(usize) -> T + Sync, lanes: bool) -> Vec<T>
    where
        T: Summand + Send + Sync,
    {
        let scatter = |c: &Chunk, acc: &mut [T], _: &mut [()]| match lanes {
            // SAFETY: `lanes` only where the CPU has AVX2.
            true => unsafe { self.chunk_columns_in_lanes(c, &w, acc) },
            false => {
                for i in c.points.clone() {
                    self.scatter_row(i, w(self.order[i] as usize), c, acc);
                }
            }
        };
        // Nothing a point: `()` takes no memory.
        self.in_waves(zero, &mut vec![(); self.order.len()], scatter)
    }

    /// A Sinkhorn row update and the column sums of its result in one pass over the rows
    /// (each row is read once, not twice): every point's exact row scaling `u*_p = volume /
    /// sum_j K_pj v_j`, by point, and every slot's `C*_j = sum_p K_pj u*_p`; the numbers of
    /// [`Self::row_sum`] then [`Self::columns`] with `w = u*`, bit for bit. With `relax`, each
    /// point also takes the scaling `relax(p, u*_p)`, and the column sums of those come too.
    pub(super) fn rows_then_columns(
        &self,
        v: &[f64],
        volume: f64,
        relax: Option<impl Fn(usize, f64) -> f64 + Sync>,
    ) -> RowUpdate {
        let lanes = cpu_has_lanes();
        let Some(relax) = relax else {
            let (exact, sums) = self.rows_and_sums(v, volume, 0.0, |_, u| u, lanes);
            return RowUpdate {
                exact,
                relaxed: None,
                sums,
            };
        };
        let pair = |p, u| Vector::<2>::new(relax(p, u), u);
        let (u, sums) = self.rows_and_sums(v, volume, Vector::<2>::zeros(), pair, lanes);
        let split = |x: &[Vector<2>], k| {
            x.par_iter()
                .with_min_len(VALUE_GRAIN)
                .map(|x| x[k])
                .collect()
        };
        RowUpdate {
            exact: split(&u, 1),
            relaxed: Some((split(&u, 0), split(&sums, 0))),
            sums: split(&sums, 1),
        }
    }

    /// The fused pass of [`Self::rows_then_columns`]: each point's `w(p, u*_p)`, by point, and
    /// their column sums; four cells at a time with `lanes` (AVX2, [`lanes`]: the same bits).
    fn rows_and_sums<T>(
        &self,
        v: &[f64],
        volume: f64,
        zero: T,
        w: impl Fn(usize, f64) -> T + Sync,
        lanes: bool,
    ) -> (Vec<T>, Vec<T>)
    where
        T: Summand + Send + Sync,
    {
        let mut sorted = vec![zero; self.order.len()];
        let sums = self.in_waves(zero, &mut sorted, |c, acc, out| match lanes {
            // SAFETY: `lanes` only where the CPU has AVX2 (`cpu_has_lanes`).
            true => unsafe { self.chunk_rows_in_lanes(c, v, volume, &w, acc, out) },
            false => {
                for (i, out) in c.points.clone().zip(out) {
                    *out = w(self.order[i] as usize, volume / self.row_sum_at(i, v));
                    self.scatter_row(i, *out, c, acc);
                }
            }
        });
        (self.by_point(&sorted), sums)
    }

    /// Column sums a wave of chunks at a time ([`wave_len`]): each chunk's `scatter` adds its
    /// points' rows into its window of slots (which has [`lanes::PAD`] spare at its end) and
    /// writes what else it computes of its points into its part of `out` (one value a sorted
    /// point); the windows are added into one value per slot in chunk order. The windows are
    /// allocated before the chunks are shared out and `out` is the caller's, so that the
    /// threads allocate nothing while they scatter: they would wait on each other for the one
    /// malloc arena (`main.rs`). Each window is allocated on its own: a large window of `f64`
    /// sums comes zeroed from fresh pages, and its slots that no point of the chunk reaches
    /// stay untouched (one buffer written zero for a wave took more memory and time,
    /// docs/benchmarks/powerpic.md).
    fn in_waves<T, O: Send>(
        &self,
        zero: T,
        mut out: &mut [O],
        scatter: impl Fn(&Chunk, &mut [T], &mut [O]) + Sync,
    ) -> Vec<T>
    where
        T: Copy + Send + Sync + AddAssign,
    {
        assert_eq!(out.len(), self.order.len(), "a value a point");
        let mut sums = vec![zero; self.active.len()];
        for wave in self.chunks.chunks(wave_len()) {
            let mut parts = Vec::with_capacity(wave.len());
            for c in wave {
                let (o, rest) = std::mem::take(&mut out).split_at_mut(c.points.len());
                out = rest;
                parts.push((c, vec![zero; c.window.len() + lanes::PAD], o));
            }
            (parts.par_iter_mut()).for_each(|(c, acc, o)| scatter(c, acc, o));
            let windows: Vec<&[T]> = parts.iter().map(|(_, acc, _)| &acc[..]).collect();
            add_windows(&mut sums, wave, &windows);
        }
        sums
    }

    /// Adds `w K_pj` of the point at sorted place `i` into the window `acc` of its chunk `c`.
    #[inline]
    fn scatter_row<T>(&self, i: usize, w: T, c: &Chunk, acc: &mut [T])
    where
        T: Copy + AddAssign + Mul<f64, Output = T>,
    {
        let (runs, factor) = self.runs_at(i);
        for run in runs {
            let kernel = self.outer(run, factor);
            let fx = &factor[run.start as usize..][..run.len as usize];
            let at = run.slot as usize - c.window.start;
            for (acc, &fx) in acc[at..at + fx.len()].iter_mut().zip(fx) {
                *acc += w * (kernel * fx as f64);
            }
        }
    }
}

/// Chunks whose windows are held at once: the column sums go a wave of chunks at a time,
/// each wave's windows added into the sums before the next is made. A chunk's window spans
/// every slot its points' balls reach, a few planes of cells across the grid's slowest axis
/// however few its points, so all the windows at once would hold about the points times a
/// plane's cells, growing as the fifth power of the resolution (docs/benchmarks/memory.md,
/// "Power PIC's column windows"). Four chunks a thread keep every thread busy; the sums are
/// the same whatever the wave's length (each slot's windows are added in chunk order).
fn wave_len() -> usize {
    (4 * rayon::current_num_threads()).max(16)
}

/// Adds the windows `parts` of the chunks `wave` into `out`, one value per slot, in chunk
/// order.
fn add_windows<T>(out: &mut [T], wave: &[Chunk], parts: &[&[T]])
where
    T: Copy + Send + Sync + AddAssign,
{
    let start = wave.iter().map(|c| c.window.start).min().unwrap_or(0);
    let end = wave.iter().map(|c| c.window.end).max().unwrap_or(0);
    (out[start..end].par_chunks_mut(SLOT_BLOCK).enumerate()).for_each(|(b, out)| {
        let block = start + b * SLOT_BLOCK..start + b * SLOT_BLOCK + out.len();
        for (c, part) in wave.iter().zip(parts) {
            let (lo, hi) = (block.start.max(c.window.start), block.end.min(c.window.end));
            for k in lo..hi {
                out[k - block.start] += part[k - c.window.start];
            }
        }
    });
}

/// What building a kernel needs of the grid: the transport grid, the cells near the points
/// numbered, the ball's squared radius `KERNEL_CUTOFF eps` (as `r * r`) and its half-width
/// in cells.
struct Ball<'a, const D: usize> {
    tg: &'a TransportGrid<D>,
    strides: [usize; D],
    near: CellNumbers,
    r2: f64,
    reach: usize,
}

impl<'a, const D: usize> Ball<'a, D> {
    fn new(tg: &'a TransportGrid<D>, points: &[Vector<D>], s: &SinkhornSettings) -> Self {
        let (r, reach) = (s.radius(), (s.radius() / tg.h).ceil() as usize);
        let cells = points.par_iter().map(|x| cell_of(tg, x));
        let spans = line_spans(&tg.grid.dims, cells);
        Self {
            tg,
            strides: strides(&tg.grid.dims),
            near: Active::around_spans(&tg.grid, spans, reach).numbers(&tg.grid),
            r2: r * r,
            reach,
        }
    }

    fn side(&self) -> usize {
        2 * self.reach + 1
    }

    /// The box of the point at `x`, with the squared distances `(x_j,k - x_k)^2` along each
    /// axis `k` over it written into `d2` (at `d2[k side + a]` for its `a`-th cell).
    fn point_box(&self, x: &Vector<D>, d2: &mut [f64]) -> PointBox<D> {
        let (c, dims) = (cell_of(self.tg, x), &self.tg.grid.dims);
        let lo: [usize; D] = std::array::from_fn(|k| c[k].saturating_sub(self.reach));
        let len: [usize; D] =
            std::array::from_fn(|k| (c[k] + self.reach).min(dims[k] - 1) + 1 - lo[k]);
        let mut left = 0;
        for (k, d2) in d2.chunks_mut(self.side()).enumerate() {
            for (i, d2) in (lo[k]..lo[k] + len[k]).zip(d2) {
                let dx = (i as f64 + 0.5) * self.tg.h - x[k];
                left += (k == 0 && dx < 0.0) as usize;
                *d2 = dx.powi(2);
            }
        }
        PointBox { lo, len, left }
    }

    /// Walks the balls of the sorted points `x`: writes each point's factors
    /// `e^(-(x_k - x_j,k)^2 / eps)` along each axis over its box into `factor` (`D` runs of
    /// [`Self::side`] a point, rounded to single precision) and lists its runs into `r`, each
    /// line of its ball cut at its blocked cells, a run's first cell named by its near number;
    /// marks the cells reached. The ball test is on the squared distances in double precision.
    fn walk(
        &self,
        x: &[Vector<D>],
        epsilon: f64,
        factor: &mut [f32],
        r: &mut Runs,
        reached: &[AtomicBool],
    ) {
        r.first.clear();
        r.run.clear();
        r.first.push(0);
        let mut d2 = vec![0.0; D * self.side()];
        for (x, f) in x.iter().zip(factor.chunks_mut(D * self.side())) {
            let b = self.point_box(x, &mut d2);
            self.lines(&b, &d2, D - 1, 0.0, [0; D], &mut |l| {
                self.line_runs(&l, reached, &mut r.run)
            });
            (f.iter_mut().zip(&d2)).for_each(|(f, d2)| *f = (-d2 / epsilon).exp() as f32);
            r.first.push(r.run.len() as u32);
        }
    }

    /// Lists the runs of the line `l` of a ball into `runs`: its free cells, cut at the
    /// blocked ones, a run's first cell named by its near number; marks the cells reached.
    fn line_runs(&self, l: &Line<D>, reached: &[AtomicBool], runs: &mut Vec<Run>) {
        let at = std::array::from_fn(|k| l.at.get(k + 1).map_or(0, |&a| a as u8));
        let line = l.cell + l.cells.start..l.cell + l.cells.end;
        let free = self.tg.free_among(line);
        let mut a = 0;
        while let Some(skip) = free[a..].iter().position(|&f| f) {
            a += skip;
            let len = free[a..].iter().position(|&f| !f).unwrap_or(free.len() - a);
            let near = l.near + a;
            (reached[near..near + len].iter()).for_each(|r| r.store(true, Ordering::Relaxed));
            runs.push(Run {
                slot: near as u32,
                start: (l.cells.start + a) as u8,
                len: len as u8,
                at,
            });
            a += len;
        }
    }

    /// Calls `f` with each line of the ball in the box `b` whose place along the axes above `k`
    /// is `at`'s, in grid order (axis 1 fastest), from the squared distances `d2` along each
    /// axis over the box (as [`Self::walk`] lays them out), `outer` the sum of those along the
    /// axes above `k` at `at`. The ball test is on the sum of the per-axis squares, the last
    /// axis first, as [`Kernel::outer`] multiplies the factors; a sum over the ball's reach
    /// stays over it as the axes below add their squares, so its lines are not looked at.
    fn lines(
        &self,
        b: &PointBox<D>,
        d2: &[f64],
        k: usize,
        outer: f64,
        mut at: [usize; D],
        f: &mut impl FnMut(Line<D>),
    ) {
        for a in 0..b.len[k] {
            at[k] = a;
            let outer = outer + d2[k * self.side() + a];
            if outer > self.r2 {
                continue;
            }
            if k > 1 {
                self.lines(b, d2, k - 1, outer, at, f);
                continue;
            }
            // The line's cells in the ball, counted rather than searched for, so that where
            // the line leaves the ball costs no branch: they are one span, the squared distance
            // falling up to the point and growing past it (`x_j,0 - x_0` as computed grows
            // along the line, rounding included), and the cells before the span are the
            // outside ones of those left of the point.
            let line = &d2[..b.len[0]];
            let outside = |d: &f64| (outer + d > self.r2) as usize;
            let inside = line.len() - line.iter().map(outside).sum::<usize>();
            if inside == 0 {
                continue;
            }
            let start: usize = line[..b.left].iter().map(outside).sum();
            let first: [usize; D] = std::array::from_fn(|k| b.lo[k] + at[k]);
            let near = (self.near.at(first)).expect("the near cells hold the ball's box");
            f(Line {
                near: near + start,
                cell: (0..D).map(|k| first[k] * self.strides[k]).sum(),
                cells: start..start + inside,
                at,
            });
        }
    }
}

/// A point's box: its first cell and its cells per axis, and how many of its cells along
/// axis 0 have their centres left of the point (`x_j,0 - x_0 < 0` as computed).
struct PointBox<const D: usize> {
    lo: [usize; D],
    len: [usize; D],
    left: usize,
}

/// A line of cells along axis 0 in a point's ball: the cells `cells` of its box along that
/// axis, whose first has the number `near` among the near cells; `cell` is the grid index of
/// the line's cell 0 of the box, `at` the line's place in the box.
struct Line<const D: usize> {
    near: usize,
    cell: usize,
    cells: Range<usize>,
    at: [usize; D],
}

/// The points' indices sorted by the cell holding them (stably); under [`VALUE_GRAIN`] points
/// on one thread (the same order: both sorts are stable), which on dam-2d's few thousand
/// points took 0.75x the parallel sort's time (25-26 ms against 33-35 over a 3 s run, issue
/// 73).
fn sorted_by_cell<const D: usize>(tg: &TransportGrid<D>, points: &[Vector<D>]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    let key = |&p: &u32| tg.grid.cell_index(cell_of(tg, &points[p as usize]));
    match points.len() < VALUE_GRAIN {
        true => order.sort_by_cached_key(key),
        false => order.par_sort_by_cached_key(key),
    }
    order
}

/// The cell of `tg` holding `x` (clamped onto the grid).
pub(super) fn cell_of<const D: usize>(tg: &TransportGrid<D>, x: &Vector<D>) -> [usize; D] {
    std::array::from_fn(|k| ((x[k] / tg.h).max(0.0) as usize).min(tg.grid.dims[k] - 1))
}

#[cfg(test)]
mod tests {
    use super::super::KERNEL_CUTOFF;
    use super::*;
    use crate::grid::Grid;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// `n` points drawn uniformly over the transport grid `tg`, and their kernel at `epsilon`.
    fn random_points_kernel<const D: usize>(
        tg: &TransportGrid<D>,
        n: usize,
        epsilon: f64,
        rng: &mut StdRng,
    ) -> (Vec<Vector<D>>, Kernel<D>) {
        let side = |k: usize| tg.grid.dims[k] as f64 * tg.h;
        let points: Vec<Vector<D>> = (0..n)
            .map(|_| Vector::<D>::from_fn(|k, _| rng.random::<f64>() * side(k)))
            .collect();
        let s = SinkhornSettings {
            epsilon,
            delta: 0.1,
            max_iterations: 1,
        };
        let kernel = Kernel::new(tg, &points, &s, Kernel::empty()).unwrap();
        (points, kernel)
    }

    /// Every point's row against the kernel written out cell by cell: the free cells within
    /// `sqrt(KERNEL_CUTOFF eps)` of it, each with `e^(-|x_p - x_j|^2 / eps)`; and the row and
    /// column sums against sums over those rows.
    fn rows_are_the_kernel_written_out<const D: usize>(dims: [usize; D], epsilon: f64) {
        let mut tg = TransportGrid::new(Grid::new(dims), 0.5);
        let mut rng = StdRng::seed_from_u64(D as u64);
        for j in 0..tg.grid.num_cells() {
            tg.set_free(j, rng.random::<f64>() > 0.2);
        }
        let (points, kernel) = random_points_kernel(&tg, 300, epsilon, &mut rng);
        let active = kernel.active();
        let v: Vec<f64> = (0..active.len()).map(|_| rng.random()).collect();
        let w: Vec<f64> = (0..points.len()).map(|_| rng.random()).collect();
        let (mut rows, mut columns) = (vec![0.0; points.len()], vec![0.0; active.len()]);
        for (p, x) in points.iter().enumerate() {
            let mut listed = vec![];
            kernel.for_each_in_row(p, |k, kpj| {
                listed.push((active[k] as usize, kpj));
                rows[p] += kpj * v[k];
                columns[k] += kpj * w[p];
            });
            let written_out: Vec<(usize, f64)> = (0..tg.grid.num_cells())
                .filter(|&j| tg.is_free(j))
                .map(|j| (j, (tg.center(j) - x).norm_squared()))
                .filter(|&(_, d2)| d2 <= KERNEL_CUTOFF * epsilon * (1.0 - 1e-12))
                .map(|(j, d2)| (j, (-d2 / epsilon).exp()))
                .collect();
            let cells = |l: &[(usize, f64)]| l.iter().map(|c| c.0).collect::<Vec<_>>();
            let inner = cells(&written_out);
            assert!(
                inner.iter().all(|j| cells(&listed).contains(j)),
                "point {p}"
            );
            for (j, kpj) in listed {
                let d2 = (tg.center(j) - x).norm_squared();
                assert!(tg.is_free(j), "point {p}: blocked cell {j} listed");
                assert!(
                    d2 <= KERNEL_CUTOFF * epsilon * (1.0 + 1e-12),
                    "point {p}, cell {j}"
                );
                // Each of the D factors rounded to f32 (relative error at most 2^-24), their
                // product and the exponentials in f64.
                let exact = (-d2 / epsilon).exp();
                let bound = D as f64 * f32::EPSILON as f64 / 2.0 + 1e-12;
                assert!((kpj / exact - 1.0).abs() <= bound, "point {p}, cell {j}");
            }
        }
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
        let sums: Vec<f64> = (0..points.len()).map(|p| kernel.row_sum(p, &v)).collect();
        assert!(sums.iter().zip(&rows).all(|(&a, &b)| close(a, b)));
        // Walked in the sorted order, each value with its point.
        let n = points.len();
        let by_rows = |r| kernel.by_rows(r, |p| (p, kernel.row_sum(p, &v)));
        let mut by_rows: Vec<_> = by_rows(0..n / 3).chain(by_rows(n / 3..n)).collect();
        assert!(by_rows.iter().all(|(p, (q, _))| p == q));
        by_rows.sort_by_key(|r| r.0);
        assert_eq!(
            by_rows.into_iter().map(|r| r.1).collect::<Vec<_>>(),
            sums.iter().copied().enumerate().collect::<Vec<_>>()
        );
        let cols = kernel.columns(0.0, |p| w[p]);
        assert!(cols.iter().zip(&columns).all(|(&a, &b)| close(a, b)));
        // The fused row update and column sums: the same numbers as the two passes, bit for bit.
        let exact = kernel.rows_then_columns(&v, 0.25, None::<fn(usize, f64) -> f64>);
        let apart: Vec<f64> = sums.iter().map(|s| 0.25 / s).collect();
        assert_eq!(exact.exact, apart);
        assert_eq!(exact.sums, kernel.columns(0.0, |p| apart[p]));
        assert!(exact.relaxed.is_none());
        // Relaxed: the same exact scalings and sums, and the sums of the scalings taken.
        let relaxed = kernel.rows_then_columns(&v, 0.25, Some(|p, u| u * w[p]));
        let taken: Vec<f64> = apart.iter().zip(&w).map(|(u, w)| u * w).collect();
        assert_eq!((&relaxed.exact, &relaxed.sums), (&exact.exact, &exact.sums));
        let (u, sums) = relaxed.relaxed.expect("relaxed rows");
        assert_eq!(
            (u, sums),
            (taken.clone(), kernel.columns(0.0, |p| taken[p]))
        );
    }

    /// Every `K_pj` of random points on an open grid against its known value: the product of
    /// its per-axis exponentials, each rounded to single precision as stored, bit for bit (the
    /// last axis first, as [`Kernel::outer`] multiplies them); and so within `D 2^-24` (to
    /// first order) of the product of the exponentials in double precision, relative to it.
    fn kernel_values_are_single_precision_factors_multiplied<const D: usize>(
        dims: [usize; D],
        epsilon: f64,
    ) {
        let tg = TransportGrid::new(Grid::new(dims), 0.5);
        let mut rng = StdRng::seed_from_u64(10 + D as u64);
        let (points, kernel) = random_points_kernel(&tg, 200, epsilon, &mut rng);
        let active = kernel.active();
        let rounding = 0.5 * f32::EPSILON as f64;
        let bound = (1.0 + rounding).powi(D as i32) - 1.0 + 4.0 * f64::EPSILON;
        let mut entries = 0;
        for (p, x) in points.iter().enumerate() {
            kernel.for_each_in_row(p, |k, kpj| {
                let c = tg.grid.cell_coords(active[k] as usize);
                let e = |k: usize| (-((c[k] as f64 + 0.5) * tg.h - x[k]).powi(2) / epsilon).exp();
                let exact: f64 = (0..D).map(e).product();
                let error = (kpj / exact - 1.0).abs();
                assert!(error <= bound, "point {p}, slot {k}: {error:e}");
                let outer = (1..D).rev().fold(1.0, |kpj, k| kpj * e(k) as f32 as f64);
                assert_eq!(kpj, outer * e(0) as f32 as f64, "point {p}, slot {k}");
                entries += 1;
            });
        }
        assert!(entries > 20 * points.len(), "{entries} entries");
    }

    #[test]
    fn kernel_values_are_single_precision_factors_multiplied_2d_and_3d() {
        kernel_values_are_single_precision_factors_multiplied([24, 18], 0.1);
        kernel_values_are_single_precision_factors_multiplied([24, 18], 0.4);
        kernel_values_are_single_precision_factors_multiplied([12, 10, 9], 0.1);
    }

    /// A value [`Summand`] adds a cell at a time.
    #[derive(Clone, Copy)]
    struct Triple([f64; 3]);

    impl AddAssign for Triple {
        fn add_assign(&mut self, o: Self) {
            (0..3).for_each(|k| self.0[k] += o.0[k]);
        }
    }

    impl Mul<f64> for Triple {
        type Output = Self;
        fn mul(self, a: f64) -> Self {
            Triple(self.0.map(|x| x * a))
        }
    }

    impl Summand for Triple {}

    /// The fused pass four cells at a time ([`lanes`]) against the one-cell code, bit for bit,
    /// with one scaling and with pairs, and the column sums alone, on grids with blocked cells
    /// (runs cut short) and at two kernel widths (boxes of 9 and 15 cells a side: runs of up to
    /// three and four groups of four).
    fn lanes_give_the_one_cell_bits<const D: usize>(dims: [usize; D], epsilon: f64) {
        let mut tg = TransportGrid::new(Grid::new(dims), 0.5);
        let mut rng = StdRng::seed_from_u64(20 + D as u64);
        for j in 0..tg.grid.num_cells() {
            tg.set_free(j, rng.random::<f64>() > 0.15);
        }
        let (points, kernel) = random_points_kernel(&tg, 700, epsilon, &mut rng);
        let v: Vec<f64> = (0..kernel.active().len()).map(|_| rng.random()).collect();
        let w: Vec<f64> = (0..points.len()).map(|_| rng.random()).collect();
        let bits = |x: &[f64]| x.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let one = |lanes| kernel.rows_and_sums(&v, 0.25, 0.0, |_, u| u, lanes);
        let (scalar, lanes) = (one(false), one(true));
        assert_eq!(bits(&scalar.0), bits(&lanes.0));
        assert_eq!(bits(&scalar.1), bits(&lanes.1));
        let pair = |p: usize, u: f64| Vector::<2>::new(u * w[p], u);
        let two = |lanes| kernel.rows_and_sums(&v, 0.25, Vector::<2>::zeros(), pair, lanes);
        let (scalar, lanes) = (two(false), two(true));
        let flat = |x: &[Vector<2>]| x.iter().flat_map(|x| [x[0], x[1]]).collect::<Vec<_>>();
        assert_eq!(bits(&flat(&scalar.0)), bits(&flat(&lanes.0)));
        assert_eq!(bits(&flat(&scalar.1)), bits(&flat(&lanes.1)));
        // The column sums alone: a scaling in lanes, and a value added a cell at a time.
        let columns = |lanes| kernel.columns_in(0.0, |p| w[p], lanes);
        assert_eq!(bits(&columns(false)), bits(&columns(true)));
        let triple = |p: usize| Triple([w[p], 1.0 - w[p], 3.0 * w[p]]);
        let triples = |lanes| kernel.columns_in(Triple([0.0; 3]), triple, lanes);
        let flat = |x: &[Triple]| x.iter().flat_map(|x| x.0).collect::<Vec<_>>();
        assert_eq!(bits(&flat(&triples(false))), bits(&flat(&triples(true))));
    }

    #[test]
    fn lanes_give_the_one_cell_bits_2d_and_3d() {
        if !cpu_has_lanes() {
            eprintln!("no AVX2 here: the four-lane code was not exercised");
            return;
        }
        lanes_give_the_one_cell_bits([40, 30], 0.1);
        lanes_give_the_one_cell_bits([40, 30], 0.4);
        lanes_give_the_one_cell_bits([16, 14, 12], 0.1);
        lanes_give_the_one_cell_bits([16, 14, 12], 0.4);
    }

    /// Every point's cells against a scan of its box with the walk's own ball test (the same
    /// squared distances, summed in the same order), as sets: points on the cells' faces, a
    /// few units in the last place either side of them, and at random, on a grid with blocked
    /// cells. On a face the point's own cell and its neighbour are about as near, so which
    /// cells lie left of the point, where a line's span is counted from, is at its finest.
    fn cells_are_the_ball_scanned<const D: usize>(dims: [usize; D], epsilon: f64) {
        // A side that rounds: the cells' centres are not exact.
        let mut tg = TransportGrid::new(Grid::new(dims), 1.0 / 3.0);
        let mut rng = StdRng::seed_from_u64(30 + D as u64);
        for j in 0..tg.grid.num_cells() {
            tg.set_free(j, rng.random::<f64>() > 0.1);
        }
        let ulps = |x: f64, n: i64| f64::from_bits((x.to_bits() as i64 + n) as u64);
        let points: Vec<Vector<D>> = (0..400)
            .map(|p| {
                Vector::<D>::from_fn(|k, _| {
                    let face = rng.random_range(1..dims[k]) as f64 * tg.h;
                    match p % 4 {
                        0 => face,
                        1 => ulps(face, -rng.random_range(1..4)),
                        2 => ulps(face, rng.random_range(1..4)),
                        _ => rng.random::<f64>() * dims[k] as f64 * tg.h,
                    }
                })
            })
            .collect();
        let s = SinkhornSettings {
            epsilon,
            delta: 0.1,
            max_iterations: 1,
        };
        let kernel = Kernel::new(&tg, &points, &s, Kernel::empty()).unwrap();
        let (r2, reach) = (s.radius() * s.radius(), (s.radius() / tg.h).ceil() as usize);
        for (p, x) in points.iter().enumerate() {
            let mut listed = vec![];
            kernel.for_each_in_row(p, |k, _| listed.push(kernel.active()[k] as usize));
            let c = cell_of(&tg, x);
            let scanned: Vec<usize> = (0..tg.grid.num_cells())
                .filter(|&j| tg.is_free(j))
                .filter(|&j| {
                    let cj = tg.grid.cell_coords(j);
                    let near = (0..D).all(|k| cj[k].abs_diff(c[k]) <= reach);
                    let d2 = |k: usize| ((cj[k] as f64 + 0.5) * tg.h - x[k]).powi(2);
                    near && (0..D).rev().fold(0.0, |sum, k| sum + d2(k)) <= r2
                })
                .collect();
            assert_eq!(listed, scanned, "point {p} at {x:?}");
        }
    }

    #[test]
    fn cells_are_the_ball_scanned_2d_and_3d() {
        cells_are_the_ball_scanned([30, 24], 0.05);
        cells_are_the_ball_scanned([30, 24], 0.2);
        cells_are_the_ball_scanned([16, 14, 12], 0.05);
    }

    #[test]
    fn rows_are_the_kernel_written_out_2d_and_3d() {
        rows_are_the_kernel_written_out([24, 18], 0.1);
        rows_are_the_kernel_written_out([24, 18], 0.4);
        rows_are_the_kernel_written_out([12, 10, 9], 0.1);
    }
}
