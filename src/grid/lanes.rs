//! Face stencils of four points at once, one point per lane of 256-bit AVX2 registers.
//!
//! Every lane performs exactly the operations of [`FacePoint`](super::FacePoint) and
//! [`FaceStencil`](super::FaceStencil) for its point, in the same order and with no fused
//! multiply-add, so the results are the same bits as the one-point code: the lanes only share
//! instructions. The two faces of a corner pair along axis 0 are neighbours in memory, so each
//! point reads them with one 16-byte load (gathers, one per corner for four points, took 1.8
//! times as long). Used where the per-particle work is a few stencils and nothing else (grid to
//! particles, paper sec. 3).
//!
//! Callers check [`available`] once and fall back to the one-point code otherwise.

use std::arch::x86_64::*;

use super::{Grid, LayerRange, MacField, Vector};

/// Whether this CPU has AVX2, checked at run time (cached by `std`).
pub fn cpu_has_lanes() -> bool {
    is_x86_feature_detected!("avx2")
}

/// Whether the four-lane code runs on `grid` here: AVX2, and face indices that fit the 32-bit
/// lanes they travel in.
pub fn available<const D: usize>(grid: &Grid<D>) -> bool {
    let fits = (0..D).all(|a| grid.num_faces(a) <= i32::MAX as usize);
    fits && cpu_has_lanes()
}

/// [`super::AxisSplit`] of four coordinates.
#[derive(Clone, Copy)]
struct AxisSplit4 {
    layer: __m128i,
    hi: __m256d,
    has_upper: bool,
}

impl AxisSplit4 {
    /// As [`super::AxisSplit::new`], lane by lane.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn new(xk: __m256d, range: &LayerRange) -> Self {
        // `max(x, 0)` returns its second operand when `x` is NaN, like `f64::max`.
        let s = _mm256_max_pd(
            _mm256_sub_pd(xk, _mm256_set1_pd(range.offset)),
            _mm256_setzero_pd(),
        );
        let s = _mm256_min_pd(s, _mm256_set1_pd(range.top));
        // `0 <= s <= top`: truncation is the floor and fits an `i32`.
        let layer = _mm_min_epi32(_mm256_cvttpd_epi32(s), _mm_set1_epi32(range.last_lower));
        Self {
            layer,
            hi: _mm256_sub_pd(s, _mm256_cvtepi32_pd(layer)),
            has_upper: range.has_upper,
        }
    }
}

/// [`super::FacePoint`] of four points.
pub struct FacePoint4<const D: usize> {
    split: [[AxisSplit4; 2]; D],
}

impl<const D: usize> FacePoint4<D> {
    /// The points `x[0..4]`.
    ///
    /// # Safety
    /// Only on a CPU with AVX2 (see [`available`]).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn new(grid: &Grid<D>, x: &[Vector<D>; 4]) -> Self {
        let mut split = [[AxisSplit4 {
            layer: _mm_setzero_si128(),
            hi: _mm256_setzero_pd(),
            has_upper: false,
        }; 2]; D];
        for (k, s) in split.iter_mut().enumerate() {
            let xk = _mm256_set_pd(x[3][k], x[2][k], x[1][k], x[0][k]);
            let ranges = &grid.layers[k];
            *s = [
                AxisSplit4::new(xk, &ranges[0]),
                AxisSplit4::new(xk, &ranges[1]),
            ];
        }
        Self { split }
    }
}

/// [`super::FaceStencil`] of four points, kept per axis (each corner's weight and face are
/// formed where they are read, so that nothing of size `2^D` is stored).
pub struct FaceStencil4<const D: usize> {
    /// The lower corner's faces.
    base: __m128i,
    /// Per axis: the step to the upper face (the same for the four points), and the weights
    /// of the lower and upper faces.
    up: [i32; D],
    lo: [__m256d; D],
    hi: [__m256d; D],
}

impl<const D: usize> FaceStencil4<D> {
    const CORNERS: usize = 1 << D;

    /// As [`super::FaceStencil::at`].
    ///
    /// # Safety
    /// Only on a CPU with AVX2 (see [`available`]).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn at(grid: &Grid<D>, point: &FacePoint4<D>, axis: usize) -> Self {
        let strides = &grid.face_strides[axis];
        let mut base = _mm_setzero_si128();
        let mut up = [0; D];
        let (mut lo, mut hi) = ([_mm256_setzero_pd(); D], [_mm256_setzero_pd(); D]);
        for (k, &stride) in strides.iter().enumerate() {
            let s = point.split[k][usize::from(k != axis)];
            // Strides fit an `i32`: every face index does (see `available`).
            let stride = stride as i32;
            base = _mm_add_epi32(base, _mm_mullo_epi32(s.layer, _mm_set1_epi32(stride)));
            up[k] = if s.has_upper { stride } else { 0 };
            lo[k] = _mm256_sub_pd(_mm256_set1_pd(1.0), s.hi);
            hi[k] = s.hi;
        }
        Self { base, up, lo, hi }
    }

    /// Corner `c`'s weight (bit `k` set: the upper face along axis `k`): `prod_k (hi_k or
    /// lo_k)`, multiplied in axis order from 1 as the one-point stencil builds it.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn weight(&self, c: usize) -> __m256d {
        let mut w = _mm256_set1_pd(1.0);
        for k in 0..D {
            w = _mm256_mul_pd(
                w,
                if c >> k & 1 == 1 {
                    self.hi[k]
                } else {
                    self.lo[k]
                },
            );
        }
        w
    }

    /// Corner `c`'s face minus the lower corner's.
    fn offset(&self, c: usize) -> i32 {
        (0..D).filter(|k| c >> k & 1 == 1).map(|k| self.up[k]).sum()
    }

    /// As [`super::FaceStencil::apply`] on two fields, for the four points: the sums run in
    /// corner order.
    ///
    /// # Safety
    /// Only on a CPU with AVX2 (see [`available`]).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn apply_pair(&self, a: &[f64], b: &[f64]) -> (__m256d, __m256d) {
        // The last corner's faces are the largest (the steps are non-negative): one check
        // covers every read. Indices are below `i32::MAX`, so a signed comparison is exact.
        let last = _mm_add_epi32(self.base, _mm_set1_epi32(self.offset(Self::CORNERS - 1)));
        let len = a.len().min(b.len()).min(i32::MAX as usize) as i32;
        let inside = _mm_cmpgt_epi32(_mm_set1_epi32(len), last);
        assert!(
            _mm_movemask_epi8(inside) == 0xffff,
            "stencil outside the field"
        );
        let (mut va, mut vb) = (_mm256_setzero_pd(), _mm256_setzero_pd());
        if self.up[0] == 1 {
            // The two faces along axis 0 are neighbours in memory: one 16-byte read per point
            // gives both, for two corners at a time.
            let mut base = [0i32; 4];
            // SAFETY: `base` holds four `i32`; the store is unaligned.
            unsafe { _mm_storeu_si128(base.as_mut_ptr().cast(), self.base) };
            for c in (0..Self::CORNERS).step_by(2) {
                let (w0, w1) = (self.weight(c), self.weight(c + 1));
                // SAFETY: corner `c + 1` is at most the last corner, within both fields.
                let (a0, a1) = unsafe { pairs(a, &base, self.offset(c)) };
                let (b0, b1) = unsafe { pairs(b, &base, self.offset(c)) };
                va = _mm256_add_pd(
                    _mm256_add_pd(va, _mm256_mul_pd(w0, a0)),
                    _mm256_mul_pd(w1, a1),
                );
                vb = _mm256_add_pd(
                    _mm256_add_pd(vb, _mm256_mul_pd(w0, b0)),
                    _mm256_mul_pd(w1, b1),
                );
            }
            return (va, vb);
        }
        for c in 0..Self::CORNERS {
            let (idx, w) = (
                _mm_add_epi32(self.base, _mm_set1_epi32(self.offset(c))),
                self.weight(c),
            );
            // SAFETY: every lane of `idx` is at most the same lane of `last`, which is within
            // both fields, checked above.
            let (xa, xb) = unsafe {
                (
                    _mm256_i32gather_pd::<8>(a.as_ptr(), idx),
                    _mm256_i32gather_pd::<8>(b.as_ptr(), idx),
                )
            };
            va = _mm256_add_pd(va, _mm256_mul_pd(w, xa));
            vb = _mm256_add_pd(vb, _mm256_mul_pd(w, xb));
        }
        (va, vb)
    }
}

/// [`MacField::interpolate_pairs`] of the points of whole groups of four; returns how many it
/// did (the caller does the rest one by one).
///
/// # Safety
/// Only on a CPU with AVX2, on a grid where [`available`].
#[target_feature(enable = "avx2")]
pub fn interpolate_pairs<const D: usize>(
    grid: &Grid<D>,
    a: &MacField<D>,
    b: &MacField<D>,
    xs: &[Vector<D>],
    out: &mut [[Vector<D>; 2]],
) -> usize {
    let n = xs.len() / 4 * 4;
    for (x, out) in xs[..n].chunks_exact(4).zip(out.chunks_exact_mut(4)) {
        let point = FacePoint4::new(grid, x.try_into().expect("groups of four"));
        let mut v = [[[0.0; 4]; D]; 2];
        for k in 0..D {
            let st = FaceStencil4::at(grid, &point, k);
            let (va, vb) = st.apply_pair(&a.comp[k], &b.comp[k]);
            (v[0][k], v[1][k]) = (lanes(va), lanes(vb));
        }
        for (i, out) in out.iter_mut().enumerate() {
            *out = [0, 1].map(|f| Vector::<D>::from_fn(|k, _| v[f][k][i]));
        }
    }
    n
}

/// `values[base[l] + off]` and `values[base[l] + off + 1]` of the four points `l`, as two
/// vectors (point `l` in lane `l`).
///
/// # Safety
/// Every `base[l] + off + 1` must be within `values`, and the CPU must have AVX2.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn pairs(values: &[f64], base: &[i32; 4], off: i32) -> (__m256d, __m256d) {
    let at = |l: usize| unsafe { values.as_ptr().add((base[l] + off) as usize) };
    let (p0, p1, p2, p3) = unsafe {
        (
            _mm_loadu_pd(at(0)),
            _mm_loadu_pd(at(1)),
            _mm_loadu_pd(at(2)),
            _mm_loadu_pd(at(3)),
        )
    };
    // Points 0 and 2 in one register, 1 and 3 in the other: the unpacks then give the lanes
    // in point order.
    let t02 = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(p0), p2);
    let t13 = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(p1), p3);
    (_mm256_unpacklo_pd(t02, t13), _mm256_unpackhi_pd(t02, t13))
}

/// The four lanes of `v`.
///
/// # Safety
/// Only on a CPU with AVX2 (see [`available`]).
#[target_feature(enable = "avx2")]
#[inline]
pub fn lanes(v: __m256d) -> [f64; 4] {
    let mut out = [0.0; 4];
    // SAFETY: `out` holds four `f64`; the store is unaligned.
    unsafe { _mm256_storeu_pd(out.as_mut_ptr(), v) };
    out
}
