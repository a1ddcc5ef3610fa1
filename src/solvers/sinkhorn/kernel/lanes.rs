//! The fused row update and column sums of [`Kernel`] four cells of a run at a time, in
//! 256-bit AVX2 registers (issue 73).
//!
//! **Why.** A point's row is about 40 runs of about 4 cells in 3D at the defaults, so the
//! one-cell loops spend about as much on each run's loop as on its cells. Here a run is
//! one group of four cells or two (a run has at most [`Ball::side`](super::Ball::side)
//! cells): each group's `K_pj = outer f_0` is made once for both halves of the pass (kept
//! for the scatter), and its four column sums are added with one load, one multiplication,
//! one addition and one store.
//!
//! **The same bits as the one-cell code.** Every lane does what the one-cell code does for its
//! cell, in the same order, with no fused multiply-add: `K_pj = outer f_0`, the row sum adds
//! `K_pj v_j` one cell at a time in grid order, and each slot's sum adds `w K_pj`. A run's
//! last group holds zeros past its end (masked loads of the factors and of `v`), which add
//! `+0` to the row sum and to the window's slots past the run: those are exact (every sum is
//! `+0` or positive), so a group is stored whole. A chunk's window has [`PAD`] spare slots
//! for the last run's group. The results are the same whether or not a CPU has AVX2, and the
//! golden digests did not change.
//!
//! **Checked once a row.** A point's runs go up the slots, each within the point's box (as the
//! kernel's walk makes them): its first and last run are checked against the chunk's window
//! and the scalings, and its cells addressed without a check a run. The row pass took 0.9x
//! its time on dam-3d at 48^3 (timers, 2026-12-02): a row is about 40 runs of 1 or 2 groups,
//! and the checks were a third of a run's instructions.

use super::{Chunk, Kernel};
use crate::grid::Vector;
use std::arch::x86_64::*;
use std::cell::Cell;
use std::ops::{AddAssign, Mul};

/// Spare slots at the end of a chunk's window: a run's last group may store up to three past
/// it.
pub(super) const PAD: usize = 3;

thread_local! {
    /// A row's groups of `K_pj`, kept by each thread from one row, chunk and solve to the
    /// next: a buffer allocated a chunk would make the threads wait on each other for the one
    /// malloc arena (`main.rs`) in every Sinkhorn iteration.
    static GROUPS: Cell<Vec<__m256d>> = const { Cell::new(Vec::new()) };
}

/// A value the column sums add: a scaling or a pair of them (relaxed, exact) in lanes, or any
/// other (a cell's mass and momentum) a cell at a time, as the one-cell code does.
pub trait Summand: Copy + AddAssign + Mul<f64, Output = Self> {
    /// `acc[c] += w * k[c]` for the four cells `k`, each as the one-cell `*acc += w * k`.
    ///
    /// # Safety
    /// Only on a CPU with AVX2; `acc` is valid for four values.
    #[inline]
    unsafe fn add_scaled(acc: *mut Self, w: Self, k: __m256d) {
        let k: [f64; 4] = std::mem::transmute(k);
        for (c, k) in k.into_iter().enumerate() {
            *acc.add(c) += w * k;
        }
    }
}

impl Summand for f64 {
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn add_scaled(acc: *mut f64, w: f64, k: __m256d) {
        let sum = _mm256_add_pd(_mm256_loadu_pd(acc), _mm256_mul_pd(_mm256_set1_pd(w), k));
        _mm256_storeu_pd(acc, sum);
    }
}

// Four pairs are eight `f64` in a row: a `Vector<2>` is its two components, nothing else.
const _: () = assert!(std::mem::size_of::<Vector<2>>() == 2 * std::mem::size_of::<f64>());

impl Summand for Vector<2> {
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn add_scaled(acc: *mut Vector<2>, w: Vector<2>, k: __m256d) {
        let (acc, w) = (acc.cast::<f64>(), _mm256_setr_pd(w[0], w[1], w[0], w[1]));
        // Each cell's `K_pj` twice, for the two components of its slot.
        let halves = [
            _mm256_permute4x64_pd::<0b01_01_00_00>(k),
            _mm256_permute4x64_pd::<0b11_11_10_10>(k),
        ];
        for (h, k) in halves.into_iter().enumerate() {
            let at = acc.add(4 * h);
            _mm256_storeu_pd(at, _mm256_add_pd(_mm256_loadu_pd(at), _mm256_mul_pd(w, k)));
        }
    }
}

impl<const D: usize> Kernel<D> {
    /// [`Kernel::rows_and_sums`]' work on the chunk `c`: each point's `w(p, u*_p)`, in the
    /// sorted order, into `out` (one a point of the chunk), added as `w K_pj` into the
    /// chunk's window `acc` (with its [`PAD`]).
    ///
    /// # Safety
    /// Only on a CPU with AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn chunk_rows_in_lanes<T: Summand>(
        &self,
        c: &Chunk,
        v: &[f64],
        volume: f64,
        w: &impl Fn(usize, f64) -> T,
        acc: &mut [T],
        out: &mut [T],
    ) {
        assert_eq!(
            acc.len(),
            c.window.len() + PAD,
            "a window with its spare slots"
        );
        assert_eq!(out.len(), c.points.len(), "a value a point of the chunk");
        let mut kernel = GROUPS.take();
        for (i, out) in c.points.clone().zip(out) {
            kernel.clear();
            let u = w(
                self.order[i] as usize,
                volume / self.row_sum_in_lanes(i, v, &mut kernel),
            );
            let runs = self.runs_at(i).0;
            in_window(runs, c);
            let (acc, mut group) = (acc.as_mut_ptr(), kernel.as_ptr());
            for run in runs {
                let acc = acc.add(run.slot as usize - c.window.start);
                for g in (0..run.len as usize).step_by(4) {
                    T::add_scaled(acc.add(g), u, *group);
                    group = group.add(1);
                }
            }
            *out = u;
        }
        GROUPS.set(kernel);
    }

    /// [`Kernel::columns`]' work on the chunk `c`: `w(p) K_pj` of its points added into its
    /// window `acc` (with its [`PAD`]).
    ///
    /// # Safety
    /// Only on a CPU with AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn chunk_columns_in_lanes<T: Summand>(
        &self,
        c: &Chunk,
        w: &impl Fn(usize) -> T,
        acc: &mut [T],
    ) {
        assert_eq!(
            acc.len(),
            c.window.len() + PAD,
            "a window with its spare slots"
        );
        for i in c.points.clone() {
            let u = w(self.order[i] as usize);
            let (runs, factor) = self.runs_at(i);
            in_window(runs, c);
            let acc = acc.as_mut_ptr();
            for run in runs {
                debug_assert!(run.start as usize + run.len as usize <= self.side);
                let outer = _mm256_set1_pd(self.outer(run, factor));
                let (fx, acc) = (
                    factor.as_ptr().add(run.start as usize),
                    acc.add(run.slot as usize - c.window.start),
                );
                for g in (0..run.len as usize).step_by(4) {
                    let k = group(outer, fx.add(g), run.len as usize - g).0;
                    T::add_scaled(acc.add(g), u, k);
                }
            }
        }
    }

    /// `sum_j K_pj v_j` of the point at sorted place `i`, as [`Kernel::row_sum_at`] adds it;
    /// each group of four cells' `K_pj` pushed onto `kernel`, zeros past a run's end.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn row_sum_in_lanes(&self, i: usize, v: &[f64], kernel: &mut Vec<__m256d>) -> f64 {
        let (runs, factor) = self.runs_at(i);
        // The runs go up the slots (the last ends within `v`), each within the point's box,
        // and have at most `side / 4` groups each (the capacity reserved).
        assert!(runs[runs.len() - 1].end() <= v.len());
        kernel.reserve(runs.len() * self.side.div_ceil(4));
        let mut next = kernel.as_mut_ptr().add(kernel.len());
        let mut sum = 0.0;
        for run in runs {
            debug_assert!(run.start as usize + run.len as usize <= self.side);
            let outer = _mm256_set1_pd(self.outer(run, factor));
            let (fx, v) = (
                factor.as_ptr().add(run.start as usize),
                v.as_ptr().add(run.slot as usize),
            );
            for g in (0..run.len as usize).step_by(4) {
                let (k, cells) = group(outer, fx.add(g), run.len as usize - g);
                let t = _mm256_mul_pd(k, _mm256_maskload_pd(v.add(g), cells));
                next.write(k);
                next = next.add(1);
                let (lo, hi) = (_mm256_castpd256_pd128(t), _mm256_extractf128_pd::<1>(t));
                sum += _mm_cvtsd_f64(lo);
                sum += _mm_cvtsd_f64(_mm_unpackhi_pd(lo, lo));
                sum += _mm_cvtsd_f64(hi);
                sum += _mm_cvtsd_f64(_mm_unpackhi_pd(hi, hi));
            }
        }
        kernel.set_len(next.offset_from(kernel.as_ptr()) as usize);
        sum
    }
}

/// Checks that a point's `runs` are within the window of its chunk `c` (their slots go up,
/// so the first and last say), which the lanes then address without a check.
#[inline]
fn in_window(runs: &[super::Run], c: &Chunk) {
    assert!(runs[0].slot as usize >= c.window.start && runs[runs.len() - 1].end() <= c.window.end);
}

/// The `K_pj = outer f_0` of four cells of a run, `fx` their factors along axis 0 of which
/// the first `left` are the run's (zeros past its end), and the mask of those in the run
/// (64-bit lanes).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn group(outer: __m256d, fx: *const f32, left: usize) -> (__m256d, __m256i) {
    let cells = _mm_cmpgt_epi32(_mm_set1_epi32(left as i32), _mm_setr_epi32(0, 1, 2, 3));
    let f = _mm256_cvtps_pd(_mm_maskload_ps(fx, cells));
    (_mm256_mul_pd(outer, f), _mm256_cvtepi32_epi64(cells))
}
