//! The MAC grid (paper sec. 3, "Background"): cells, staggered faces and their indexing,
//! generic over the dimension `D`.
//!
//! Everything here is in grid units: the cell size is 1 and cell `c` covers
//! `[c_k, c_k + 1)` on every axis `k`. The face with index `i` on axis `a` lies at
//! coordinate `i` along `a` (between cells `i - 1` and `i`) and at cell centres on the other
//! axes. Linear indices run with axis 0 fastest.

use nalgebra::SVector;

pub mod active;
#[cfg(target_arch = "x86_64")]
pub mod lanes;
use rayon::prelude::*;

/// A point or vector in grid units (cells).
pub type Vector<const D: usize> = SVector<f64, D>;

/// Integer cell coordinates.
pub type Cell<const D: usize> = [usize; D];

/// Cell and face layout of a `D`-dimensional MAC grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<const D: usize> {
    /// Cells per axis.
    pub dims: [usize; D],
    /// `dims` as coordinates (the domain is `[0, extent)`), converted once.
    extent: [f64; D],
    cell_strides: [usize; D],
    face_dims: [[usize; D]; D],
    face_strides: [[usize; D]; D],
    /// Per axis `k`: the face layers of component `k` (`[k][0]`) and of the others (`[k][1]`).
    layers: [[LayerRange; 2]; D],
}

/// The linear index strides of an array of `dims` cells, the first axis fastest.
pub fn strides<const D: usize>(dims: &[usize; D]) -> [usize; D] {
    let mut s = [1; D];
    for k in 1..D {
        s[k] = s[k - 1] * dims[k - 1];
    }
    s
}

/// A set of a grid's cells, with which lines of cells along axis 0 hold any of them: what
/// [`Grid::par_for_each_face_pair_near`] reads to skip whole lines of faces (built once, for
/// every face component).
pub struct NearCells {
    /// One flag per cell.
    cells: Vec<bool>,
    /// One flag per line of cells along axis 0: whether it holds a flagged cell.
    lines: Vec<bool>,
}

impl NearCells {
    /// The cells flagged in `cells` (one flag per cell of `grid`).
    pub fn new<const D: usize>(grid: &Grid<D>, cells: Vec<bool>) -> Self {
        assert_eq!(cells.len(), grid.num_cells());
        let n0 = grid.dims[0];
        let lines = (cells
            .par_chunks(n0)
            .with_min_len(crate::PAR_GRAIN.div_ceil(n0)))
        .map(|line| line.contains(&true))
        .collect();
        NearCells { cells, lines }
    }

    /// Whether cell `c` is in the set.
    pub fn holds(&self, c: usize) -> bool {
        self.cells[c]
    }

    /// Whether line `l` of cells along axis 0 holds a cell of the set.
    pub fn line_holds(&self, l: usize) -> bool {
        self.lines[l]
    }
}

impl<const D: usize> Grid<D> {
    pub fn new(dims: [usize; D]) -> Self {
        assert!(dims.iter().all(|&n| n >= 1), "grid dims must be positive");
        let face_dims = std::array::from_fn(|a| {
            let mut d = dims;
            d[a] += 1;
            d
        });
        Self {
            dims,
            extent: dims.map(|n| n as f64),
            cell_strides: strides(&dims),
            face_strides: std::array::from_fn(|a| strides(&face_dims[a])),
            face_dims,
            layers: dims.map(|n| [LayerRange::new(n, 0.0), LayerRange::new(n - 1, 0.5)]),
        }
    }

    pub fn num_cells(&self) -> usize {
        self.dims.iter().product()
    }

    /// Number of faces normal to `axis`.
    pub fn num_faces(&self, axis: usize) -> usize {
        self.face_dims[axis].iter().product()
    }

    pub fn face_dims(&self, axis: usize) -> [usize; D] {
        self.face_dims[axis]
    }

    pub fn cell_stride(&self, axis: usize) -> usize {
        self.cell_strides[axis]
    }

    pub fn face_stride(&self, face_axis: usize, along: usize) -> usize {
        self.face_strides[face_axis][along]
    }

    pub fn cell_index(&self, c: Cell<D>) -> usize {
        (0..D).map(|k| c[k] * self.cell_strides[k]).sum()
    }

    pub fn cell_coords(&self, mut idx: usize) -> Cell<D> {
        let mut c = [0; D];
        for k in 0..D {
            c[k] = idx % self.dims[k];
            idx /= self.dims[k];
        }
        c
    }

    pub fn face_index(&self, axis: usize, f: Cell<D>) -> usize {
        (0..D).map(|k| f[k] * self.face_strides[axis][k]).sum()
    }

    pub fn face_coords(&self, axis: usize, mut idx: usize) -> Cell<D> {
        let mut f = [0; D];
        for k in 0..D {
            f[k] = idx % self.face_dims[axis][k];
            idx /= self.face_dims[axis][k];
        }
        f
    }

    /// The coordinates of the faces of component `axis` from index `start` on, in index order:
    /// one division at the start, then an odometer (grid-wide face loops are hot).
    pub fn face_coords_from(&self, axis: usize, start: usize) -> impl Iterator<Item = Cell<D>> {
        let dims = self.face_dims[axis];
        let mut f = self.face_coords(axis, start);
        std::iter::from_fn(move || {
            let here = f;
            for k in 0..D {
                f[k] += 1;
                if f[k] < dims[k] {
                    break;
                }
                f[k] = 0;
            }
            Some(here)
        })
    }

    /// Calls `f(face_index, face_coords, value)` for every face of component `axis` with its
    /// entry of `values` (one per face), in parallel over layers of the last axis.
    pub fn par_for_each_face<T: Send>(
        &self,
        axis: usize,
        values: &mut [T],
        f: impl Fn(usize, Cell<D>, &mut T) + Sync,
    ) {
        let mut none = vec![(); values.len()];
        self.par_for_each_face_pair(axis, values, &mut none, |i, c, v, _| f(i, c, v));
    }

    /// As [`Self::par_for_each_face`] with two entries per face, one of `a` and one of `b`.
    pub fn par_for_each_face_pair<T: Send, U: Send>(
        &self,
        axis: usize,
        a: &mut [T],
        b: &mut [U],
        f: impl Fn(usize, Cell<D>, &mut T, &mut U) + Sync,
    ) {
        let layer = self.face_strides[axis][D - 1];
        self.par_face_chunks(axis, a, b, layer, |_| true, f);
    }

    /// As [`Self::par_for_each_face`], but only for the faces next to a cell of `near`
    /// ([`Self::par_for_each_face_pair_near`]).
    pub fn par_for_each_face_near<T: Send>(
        &self,
        axis: usize,
        values: &mut [T],
        near: &NearCells,
        f: impl Fn(usize, Cell<D>, &mut T) + Sync,
    ) {
        let mut none = vec![(); values.len()];
        self.par_for_each_face_pair_near(axis, values, &mut none, near, |i, c, v, _| f(i, c, v));
    }

    /// As [`Self::par_for_each_face_pair`], but only for the faces next to a cell of `near`,
    /// in the same order: a line of faces along axis 0 whose cells on either side hold none is
    /// skipped whole, so that a pass over a liquid filling a few percent of the grid does not
    /// walk the rest of it.
    pub fn par_for_each_face_pair_near<T: Send, U: Send>(
        &self,
        axis: usize,
        a: &mut [T],
        b: &mut [U],
        near: &NearCells,
        f: impl Fn(usize, Cell<D>, &mut T, &mut U) + Sync,
    ) {
        assert_eq!(near.cells.len(), self.num_cells());
        // The lines of cells beside the line of faces starting at `f0`: its own, and the one
        // below along `axis` (for axis 0 both are the same line).
        let line = |c: Cell<D>| near.lines[self.cell_index(c) / self.dims[0]];
        let beside = |f0: Cell<D>| {
            let below = (f0[axis] > 0).then(|| {
                let mut c = f0;
                c[axis] -= 1;
                c
            });
            (f0[axis] < self.dims[axis] && line(f0)) || below.is_some_and(line)
        };
        let len = self.face_dims[axis][0];
        self.par_face_chunks(axis, a, b, len, beside, |i, c, v, w| {
            if self.face_cells_at(axis, c).any(|k| near.cells[k]) {
                f(i, c, v, w);
            }
        });
    }

    /// Calls `f(face_index, face_coords, a_entry, b_entry)` for the faces of component `axis`
    /// in chunks of `chunk` consecutive faces, the chunks in parallel, skipping each chunk
    /// for whose first face's coordinates `keep` is false.
    fn par_face_chunks<T: Send, U: Send>(
        &self,
        axis: usize,
        a: &mut [T],
        b: &mut [U],
        chunk: usize,
        keep: impl Fn(Cell<D>) -> bool + Sync,
        f: impl Fn(usize, Cell<D>, &mut T, &mut U) + Sync,
    ) {
        assert_eq!(a.len(), self.num_faces(axis));
        assert_eq!(b.len(), self.num_faces(axis));
        a.par_chunks_mut(chunk)
            .zip(b.par_chunks_mut(chunk))
            .with_min_len(crate::PAR_GRAIN.div_ceil(chunk))
            .enumerate()
            .for_each(|(l, (a, b))| {
                let start = l * chunk;
                let mut coords = self.face_coords_from(axis, start).peekable();
                if !keep(*coords.peek().expect("a chunk has faces")) {
                    return;
                }
                for (((j, v), w), c) in a.iter_mut().enumerate().zip(b).zip(coords) {
                    f(start + j, c, v, w);
                }
            });
    }

    /// Whether `x` lies inside the domain `[0, dims)`.
    pub fn contains(&self, x: &Vector<D>) -> bool {
        (0..D).all(|k| x[k] >= 0.0 && x[k] < self.extent[k])
    }

    /// The cell containing `x`, or `None` outside the domain (or for a non-finite point).
    pub fn cell_of(&self, x: &Vector<D>) -> Option<Cell<D>> {
        if !self.contains(x) {
            return None;
        }
        // Inside the domain `0 <= x_k < dims_k < 2^31`, so truncation is the floor; through
        // i32, whose conversion is one instruction (usize's checks the sign first).
        let mut c = [0; D];
        for k in 0..D {
            c[k] = x[k] as i32 as usize;
        }
        Some(c)
    }

    /// The linear index of the cell containing `x`; panics outside the domain (a bug).
    pub fn cell_index_of(&self, x: &Vector<D>) -> usize {
        let c = self
            .cell_of(x)
            .unwrap_or_else(|| panic!("point {:?} is outside the domain", x.as_slice()));
        self.cell_index(c)
    }

    /// The neighbour of `c` one step along `axis` (`dir` = -1 or +1), if inside the domain.
    pub fn neighbor(&self, c: Cell<D>, axis: usize, dir: i32) -> Option<Cell<D>> {
        let mut n = c;
        if dir < 0 {
            n[axis] = c[axis].checked_sub(1)?;
        } else {
            n[axis] += 1;
            if n[axis] >= self.dims[axis] {
                return None;
            }
        }
        Some(n)
    }

    /// The cells on the two sides of face `i` of axis `a` (one on the domain boundary).
    pub fn face_cells(&self, a: usize, i: usize) -> impl Iterator<Item = usize> {
        self.face_cells_at(a, self.face_coords(a, i))
    }

    /// As [`Self::face_cells`] for the face at coordinates `f` (no division).
    pub fn face_cells_at(&self, a: usize, f: Cell<D>) -> impl Iterator<Item = usize> {
        let right = (f[a] < self.dims[a]).then(|| self.cell_index(f));
        let left = (f[a] > 0).then(|| {
            let mut c = f;
            c[a] -= 1;
            self.cell_index(c)
        });
        left.into_iter().chain(right)
    }

    /// The centre of the face of axis `a` with coordinates `f`, in grid units.
    pub fn face_point(&self, a: usize, f: Cell<D>) -> Vector<D> {
        Vector::<D>::from_fn(|k, _| f[k] as f64 + if k == a { 0.0 } else { 0.5 })
    }

    /// Cell centre in grid units.
    pub fn center(&self, c: Cell<D>) -> Vector<D> {
        Vector::<D>::from_fn(|k, _| c[k] as f64 + 0.5)
    }

    /// The von Neumann neighbours of cell `c` inside the domain, axis by axis, the lower one
    /// first (nbflip's re-march sums them in this order); by strides, from one conversion to
    /// coordinates.
    pub fn face_neighbors(&self, c: usize) -> impl Iterator<Item = usize> + '_ {
        let cc = self.cell_coords(c);
        (0..2 * D).filter_map(move |j| {
            let (a, s) = (j / 2, self.cell_stride(j / 2));
            match j % 2 {
                0 => (cc[a] > 0).then(|| c - s),
                _ => (cc[a] + 1 < self.dims[a]).then(|| c + s),
            }
        })
    }

    /// The cells of `member` that `seeds` (cells of `member`) reach by faces through cells of
    /// `member`, ascending: their connected components, at the cost of those alone.
    pub fn components_of(
        &self,
        seeds: impl IntoIterator<Item = usize>,
        member: impl Fn(usize) -> bool,
    ) -> Vec<usize> {
        let mut seen = std::collections::HashSet::new();
        let mut stack: Vec<usize> = seeds.into_iter().filter(|&c| seen.insert(c)).collect();
        while let Some(c) = stack.pop() {
            let new = self
                .face_neighbors(c)
                .filter(|&n| member(n) && seen.insert(n));
            stack.extend(new);
        }
        let mut cells: Vec<usize> = seen.into_iter().collect();
        cells.sort_unstable();
        cells
    }

    /// All cells of the Moore neighbourhood of `c` inside the domain, `c` excluded.
    pub fn moore_neighbors(&self, c: Cell<D>) -> impl Iterator<Item = Cell<D>> + '_ {
        let n = 3usize.pow(D as u32);
        (0..n).filter_map(move |code| {
            let mut m = code;
            let mut out = c;
            let mut all_zero = true;
            for k in 0..D {
                let off = (m % 3) as i64 - 1;
                m /= 3;
                if off != 0 {
                    all_zero = false;
                }
                let v = c[k] as i64 + off;
                if v < 0 || v >= self.dims[k] as i64 {
                    return None;
                }
                out[k] = v as usize;
            }
            (!all_zero).then_some(out)
        })
    }

    /// The point of cell `c` closest to `q` (paper eq. best_cell_pos, `phi_close`, with
    /// `margin` = epsilon): a component where `q` lies within the cell's extent is kept as it is,
    /// even within `margin` of a wall; one outside it (`|v_k| >= 0.5` with `v = q - centre`) goes to
    /// the near wall, `margin` inside.
    pub fn closest_in_cell(&self, q: &Vector<D>, c: Cell<D>, margin: f64) -> Vector<D> {
        Vector::<D>::from_fn(|k, _| closest_along(q[k], c[k], margin))
    }
}

/// One component of [`Grid::closest_in_cell`]: the point of `[c, c + 1]` closest to `q`,
/// `margin` inside when `q` is outside.
pub fn closest_along(q: f64, c: usize, margin: f64) -> f64 {
    let (lo, hi) = (c as f64, (c + 1) as f64);
    if q >= hi {
        hi - margin
    } else if q <= lo {
        lo + margin
    } else {
        q
    }
}

/// The larger of two non-negative values, NaN if either is (`f64::max` would drop the NaN,
/// and a solver or a speed check would then report a NaN field as finite).
pub fn nan_max(m: f64, v: f64) -> f64 {
    if m.is_nan() || v.is_nan() {
        f64::NAN
    } else {
        m.max(v)
    }
}

/// The largest absolute value of `values` (0 for none), NaN if any is NaN; in parallel.
pub fn max_abs(values: &[f64]) -> f64 {
    (values.par_iter().with_min_len(crate::PAR_GRAIN))
        .map(|v| v.abs())
        .reduce(|| 0.0, nan_max)
}

/// A velocity field stored on the faces of a MAC grid: component `a` lives on the faces normal
/// to axis `a`.
#[derive(Clone, Debug, PartialEq)]
pub struct MacField<const D: usize> {
    pub comp: [Vec<f64>; D],
}

impl<const D: usize> MacField<D> {
    pub fn zeros(grid: &Grid<D>) -> Self {
        Self {
            comp: std::array::from_fn(|a| vec![0.0; grid.num_faces(a)]),
        }
    }

    /// Largest absolute face value over all components; NaN if any value is NaN.
    pub fn max_abs(&self) -> f64 {
        self.comp.iter().map(|c| max_abs(c)).fold(0.0, nan_max)
    }

    /// Multilinear interpolation of the field at `x` (grid units).
    #[inline]
    pub fn interpolate(&self, grid: &Grid<D>, x: &Vector<D>) -> Vector<D> {
        let at = FacePoint::new(grid, x);
        Vector::<D>::from_fn(|a, _| FaceStencil::at(grid, &at, a).apply(&self.comp[a]))
    }

    /// `[self(x), other(x)]` at every point `x` of `xs`, into `out`: the same bits as
    /// [`MacField::interpolate`] of each field, with one located point and one stencil per
    /// component serving both, and four points at a time ([`lanes`]) where the CPU has AVX2.
    pub fn interpolate_pairs(
        &self,
        other: &Self,
        grid: &Grid<D>,
        xs: &[Vector<D>],
        out: &mut [[Vector<D>; 2]],
    ) {
        assert_eq!(xs.len(), out.len(), "one pair per point");
        #[cfg(target_arch = "x86_64")]
        let done = match lanes::available(grid) {
            // SAFETY: the CPU has AVX2, checked just above.
            true => unsafe { lanes::interpolate_pairs(grid, self, other, xs, out) },
            false => 0,
        };
        #[cfg(not(target_arch = "x86_64"))]
        let done = 0;
        for (x, out) in xs[done..].iter().zip(&mut out[done..]) {
            let point = FacePoint::new(grid, x);
            let (mut a, mut b) = (Vector::<D>::zeros(), Vector::<D>::zeros());
            for k in 0..D {
                let st = FaceStencil::at(grid, &point, k);
                (a[k], b[k]) = (st.apply(&self.comp[k]), st.apply(&other.comp[k]));
            }
            *out = [a, b];
        }
    }

    /// Multilinear interpolation of component `a` at `x`.
    #[inline]
    pub fn interpolate_component(&self, grid: &Grid<D>, a: usize, x: &Vector<D>) -> f64 {
        FaceStencil::new(grid, a, x).apply(&self.comp[a])
    }
}

/// [`MacField::interpolate`] at the faces of one component or at the cell centres (where
/// semi-Lagrangian advection starts its trace back), without locating each point: at a point
/// at least one cell from every wall no layer is clamped, so its stencils are those of one such
/// point shifted by the difference of their indices (the same faces, weights and order: the
/// same values, bit for bit). Points nearer a wall, or any point of a grid under 3 cells wide,
/// take the general path.
pub struct AtGridPoints<const D: usize> {
    /// The faces' axis, or `None` for the cell centres.
    axis: Option<usize>,
    /// Per component, its stencil at the point with coordinates `[1; D]`, if that is inner.
    inner: Option<[FaceStencil<D>; D]>,
}

impl<const D: usize> AtGridPoints<D> {
    /// At the faces of axis `axis`.
    pub fn faces(grid: &Grid<D>, axis: usize) -> Self {
        Self::new(grid, Some(axis))
    }

    /// At the cell centres.
    pub fn centres(grid: &Grid<D>) -> Self {
        Self::new(grid, None)
    }

    fn new(grid: &Grid<D>, axis: Option<usize>) -> Self {
        let mut at = Self { axis, inner: None };
        at.inner = grid.dims.iter().all(|&n| n >= 3).then(|| {
            let point = FacePoint::new(grid, &at.point(grid, [1; D]));
            std::array::from_fn(|b| FaceStencil::at(grid, &point, b))
        });
        at
    }

    /// The point with coordinates `f`.
    fn point(&self, grid: &Grid<D>, f: Cell<D>) -> Vector<D> {
        match self.axis {
            Some(a) => grid.face_point(a, f),
            None => grid.center(f),
        }
    }

    /// The field `u` at the point with coordinates `f`.
    #[inline]
    pub fn interpolate(&self, grid: &Grid<D>, u: &MacField<D>, f: Cell<D>) -> Vector<D> {
        match &self.inner {
            Some(inner) if (0..D).all(|k| 1 <= f[k] && f[k] + 2 <= grid.dims[k]) => {
                Vector::<D>::from_fn(|b, _| {
                    let shift = (0..D).map(|k| (f[k] - 1) * grid.face_strides[b][k]).sum();
                    inner[b].shifted(shift).apply(&u.comp[b])
                })
            }
            _ => u.interpolate(grid, &self.point(grid, f)),
        }
    }
}

/// The face layers of one component along one axis, in the form locating a point needs (set up
/// once in [`Grid::new`], so that locating a point converts no grid sizes): faces at
/// `offset + i` for `i = 0..=top`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LayerRange {
    offset: f64,
    /// `top` as a coordinate: points beyond it are clamped onto the last layer.
    top: f64,
    /// The last layer that can be a stencil's lower one (`top - 1`, or 0 for a single layer).
    last_lower: i32,
    has_upper: bool,
}

impl LayerRange {
    fn new(top: usize, offset: f64) -> Self {
        Self {
            offset,
            top: top as f64,
            last_lower: i32::try_from(top.saturating_sub(1)).expect("grid axis too long"),
            has_upper: top > 0,
        }
    }
}

/// Where a point lies among the face layers along one axis: the lower face's layer, the upper
/// face's weight (the lower one has `1 - hi`), and whether an upper face exists.
#[derive(Clone, Copy, Debug, Default)]
struct AxisSplit {
    layer: usize,
    hi: f64,
    has_upper: bool,
}

impl AxisSplit {
    /// Coordinate `xk` among the layers of `range`, clamped onto the outermost ones.
    #[inline]
    fn new(xk: f64, range: &LayerRange) -> Self {
        let s = (xk - range.offset).max(0.0).min(range.top);
        // `0 <= s`, so truncation is the floor. A single layer keeps weight 1 on it (`s` = 0).
        let layer = (s as i32).min(range.last_lower);
        Self {
            layer: layer as usize,
            hi: s - f64::from(layer),
            has_upper: range.has_upper,
        }
    }

    /// Along axis `k` of the grid: faces at integer positions on a component's own axis (one
    /// more layer than cells), at half-integers on the others.
    #[inline]
    fn along<const D: usize>(grid: &Grid<D>, k: usize, xk: f64, own_axis: bool) -> Self {
        Self::new(xk, &grid.layers[k][usize::from(!own_axis)])
    }
}

/// A point's place among the face layers of every component, computed once per point: along
/// axis `k`, component `k`'s faces sit at integers and the other components' at half-integers,
/// so `2 D` splits serve all `D` stencils (instead of `D^2`).
#[derive(Clone, Copy, Debug)]
pub struct FacePoint<const D: usize> {
    /// Per axis `k`: the split for the faces of component `k`, and for the other components.
    split: [[AxisSplit; 2]; D],
}

impl<const D: usize> FacePoint<D> {
    #[inline]
    pub fn new(grid: &Grid<D>, x: &Vector<D>) -> Self {
        // A plain loop: `array::from_fn` with a closure is not always inlined here.
        let mut split = [[AxisSplit::default(); 2]; D];
        for (k, s) in split.iter_mut().enumerate() {
            *s = [true, false].map(|own| AxisSplit::along(grid, k, x[k], own));
        }
        Self { split }
    }
}

/// The `2^D` faces of velocity component `axis` around a point, with the multilinear ("tent")
/// weights of paper sec. 3 (P2G and G2P). Weights sum to 1; points near the domain walls are
/// clamped onto the outermost faces. Built once per particle and component, it serves every
/// field read or written there (G2P reads the new and the old field with one stencil).
#[derive(Clone, Copy, Debug)]
pub struct FaceStencil<const D: usize> {
    idx: [usize; 8],
    w: [f64; 8],
}

impl<const D: usize> FaceStencil<D> {
    /// `2^D`; the arrays hold up to 3 dimensions.
    const CORNERS: usize = {
        assert!(D <= 3, "face stencils are for 1 to 3 dimensions");
        1 << D
    };

    /// The stencil of component `axis` at `x`.
    #[inline]
    pub fn new(grid: &Grid<D>, axis: usize, x: &Vector<D>) -> Self {
        Self::from_splits(grid, axis, |k| AxisSplit::along(grid, k, x[k], k == axis))
    }

    /// The stencil of component `axis` at a point located once for all components.
    #[inline]
    pub fn at(grid: &Grid<D>, point: &FacePoint<D>, axis: usize) -> Self {
        Self::from_splits(grid, axis, |k| point.split[k][usize::from(k != axis)])
    }

    /// Corner `c` (bit `k` set: the upper face along axis `k`) has the weight
    /// `prod_k (hi_k or 1 - hi_k)`, multiplied in axis order: the corners are built axis by
    /// axis, each axis doubling the corners found so far.
    #[inline]
    fn from_splits(grid: &Grid<D>, axis: usize, split: impl Fn(usize) -> AxisSplit) -> Self {
        let strides = &grid.face_strides[axis];
        let (mut idx, mut w) = ([0usize; 8], [1.0f64; 8]);
        for k in 0..D {
            let s = split(k);
            let (m, up) = (1 << k, if s.has_upper { strides[k] } else { 0 });
            for c in 0..m {
                idx[c] += s.layer * strides[k];
                idx[c + m] = idx[c] + up;
                w[c + m] = w[c] * s.hi;
                w[c] *= 1.0 - s.hi;
            }
        }
        Self { idx, w }
    }

    /// The same weights on the faces `shift` indices further.
    #[inline]
    fn shifted(&self, shift: usize) -> Self {
        Self {
            idx: self.idx.map(|i| i + shift),
            w: self.w,
        }
    }

    /// The faces and their weights.
    pub fn weights(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        (0..Self::CORNERS).map(|c| (self.idx[c], self.w[c]))
    }

    /// `sum_c w_c values[face_c]`, in corner order.
    #[inline]
    pub fn apply(&self, values: &[f64]) -> f64 {
        // Every corner adds non-negative strides to the first, so the last corner's face is the
        // largest: one bound check covers all `2^D` reads.
        assert!(
            self.idx[Self::CORNERS - 1] < values.len(),
            "stencil outside the field"
        );
        let mut v = 0.0;
        for c in 0..Self::CORNERS {
            // SAFETY: `idx[c] <= idx[CORNERS - 1] < values.len()`, checked above.
            v += self.w[c] * unsafe { values.get_unchecked(self.idx[c]) };
        }
        v
    }
}

/// Calls `f(cell_index, weight)` for the up to `2^D` cells whose centres lie within one cell
/// of `x` on every axis, with the multilinear ("tent") weights `prod_k (1 - |x_k - c_k - 1/2|)`.
/// Unlike [`for_each_face_weight`], nothing is clamped: the share of cells outside the domain
/// is dropped (IDP's density estimate, which accounts for the walls separately).
#[inline]
pub fn for_each_cell_weight<const D: usize>(
    grid: &Grid<D>,
    x: &Vector<D>,
    mut f: impl FnMut(usize, f64),
) {
    // Per axis, the lower cell's fraction and whether the lower and the upper cell are inside;
    // the corners' indices from the lower corner's by one stride per upper axis (wrapping: a
    // corner outside is never read).
    let mut base = 0usize;
    let mut frac = [0.0f64; D];
    let mut inside = [[false; 2]; D];
    for k in 0..D {
        let s = x[k] - 0.5;
        let lower = s.floor() as i64;
        frac[k] = s - lower as f64;
        let n = grid.dims[k] as i64;
        inside[k] = [(0..n).contains(&lower), (0..n).contains(&(lower + 1))];
        base = base.wrapping_add((lower as usize).wrapping_mul(grid.cell_stride(k)));
    }
    'corners: for corner in 0..1usize << D {
        let (mut w, mut idx) = (1.0, base);
        for k in 0..D {
            let up = (corner >> k) & 1;
            if !inside[k][up] {
                continue 'corners;
            }
            if up == 1 {
                w *= frac[k];
                idx = idx.wrapping_add(grid.cell_stride(k));
            } else {
                w *= 1.0 - frac[k];
            }
        }
        if w != 0.0 {
            f(idx, w);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_field_at_faces_and_centres_is_its_interpolation_there_bit_for_bit_2d_and_3d() {
        fn same<const D: usize>(got: Vector<D>, want: Vector<D>) {
            assert_eq!(
                got.map(f64::to_bits),
                want.map(f64::to_bits),
                "{got} against {want}"
            );
        }
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let mut u = MacField::zeros(&g);
            for (a, comp) in u.comp.iter_mut().enumerate() {
                for (i, v) in comp.iter_mut().enumerate() {
                    *v = ((i * 7 + a * 3) as f64 * 0.37).sin() * 1e3;
                }
            }
            for a in 0..D {
                let at = AtGridPoints::faces(&g, a);
                for i in 0..g.num_faces(a) {
                    let f = g.face_coords(a, i);
                    same(
                        at.interpolate(&g, &u, f),
                        u.interpolate(&g, &g.face_point(a, f)),
                    );
                }
            }
            let at = AtGridPoints::centres(&g);
            for c in 0..g.num_cells() {
                let cc = g.cell_coords(c);
                same(at.interpolate(&g, &u, cc), u.interpolate(&g, &g.center(cc)));
            }
        }
        check([5, 4]);
        check([6, 3, 5]);
        check([2, 6, 4]);
    }

    #[test]
    fn pairs_are_each_field_interpolated_bit_for_bit_2d_and_3d() {
        // Points inside, on faces, at the walls and beyond them, 4k + 3 of them (so that the
        // four-lane groups leave a rest); two unrelated fields.
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let field = |seed: f64| {
                let mut u = MacField::zeros(&g);
                for (a, comp) in u.comp.iter_mut().enumerate() {
                    for (i, v) in comp.iter_mut().enumerate() {
                        *v = ((i * 7 + a * 3) as f64 * seed).sin() * 1e3;
                    }
                }
                u
            };
            let (u, v) = (field(0.37), field(1.91));
            let xs: Vec<Vector<D>> = (0..4 * 50 + 3)
                .map(|i| {
                    Vector::from_fn(|k, _| {
                        let t = ((i * (k + 3)) as f64 * 0.618).fract();
                        (t * 1.4 - 0.2) * dims[k] as f64 + if i % 5 == 0 { 0.5 } else { 0.0 }
                    })
                })
                .collect();
            let mut out = vec![[Vector::<D>::zeros(); 2]; xs.len()];
            u.interpolate_pairs(&v, &g, &xs, &mut out);
            for (x, [a, b]) in xs.iter().zip(out) {
                let bits = |w: Vector<D>| w.map(f64::to_bits);
                assert_eq!(bits(a), bits(u.interpolate(&g, x)), "u at {x}");
                assert_eq!(bits(b), bits(v.interpolate(&g, x)), "v at {x}");
            }
        }
        check([7, 5]);
        check([6, 4, 5]);
        check([1, 6, 3]);
    }

    /// The cells and weights, in order, of the tent kernel at points inside, on cell centres
    /// and on the walls, and beyond them (whose share outside is dropped), 2D and 3D (one cell
    /// wide included): the same, bit for bit, as testing every corner's cell against the grid;
    /// and at points at least half a cell inside, weights summing to 1.
    #[test]
    fn cell_weights_are_the_tent_kernel_inside_the_grid_2d_and_3d() {
        fn reference<const D: usize>(g: &Grid<D>, x: &Vector<D>) -> Vec<(usize, u64)> {
            let mut out = vec![];
            'corners: for corner in 0..1usize << D {
                let (mut w, mut idx) = (1.0f64, 0);
                for k in 0..D {
                    let s = x[k] - 0.5;
                    let i = s.floor() as i64 + ((corner >> k) & 1) as i64;
                    if i < 0 || i >= g.dims[k] as i64 {
                        continue 'corners;
                    }
                    let frac = s - s.floor();
                    w *= if (corner >> k) & 1 == 1 {
                        frac
                    } else {
                        1.0 - frac
                    };
                    idx += i as usize * g.cell_stride(k);
                }
                if w != 0.0 {
                    out.push((idx, w.to_bits()));
                }
            }
            out
        }
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let ends = |k: usize| {
                let n = g.dims[k] as f64;
                [-0.7, -0.3, 0.0, 0.5, 1.0, n - 0.5, n, n + 0.4]
            };
            for i in 0..400 {
                let x = Vector::<D>::from_fn(|k, _| match i % 3 {
                    0 => ends(k)[(i / 3 + k) % 8],
                    _ => ((i * 13 + k * 7) as f64 * 0.37).sin() * 0.6 * g.dims[k] as f64 + 0.5,
                });
                let mut got = vec![];
                for_each_cell_weight(&g, &x, |c, w| got.push((c, w.to_bits())));
                assert_eq!(got, reference(&g, &x), "at {x}");
                if (0..D).all(|k| (0.5..=g.dims[k] as f64 - 0.5).contains(&x[k])) {
                    let sum: f64 = got.iter().map(|&(_, w)| f64::from_bits(w)).sum();
                    assert!((sum - 1.0).abs() < 1e-12, "weights sum to {sum} at {x}");
                }
            }
        }
        check([5, 7]);
        check([1, 6]);
        check([4, 3, 6]);
        check([6, 1, 5]);
    }

    #[test]
    fn indices_round_trip_2d_and_3d() {
        let g2 = Grid::new([5, 7]);
        for i in 0..g2.num_cells() {
            assert_eq!(g2.cell_index(g2.cell_coords(i)), i);
        }
        let g3 = Grid::new([3, 4, 5]);
        for a in 0..3 {
            for i in 0..g3.num_faces(a) {
                assert_eq!(g3.face_index(a, g3.face_coords(a, i)), i);
            }
        }
        assert_eq!(g3.num_faces(0), 4 * 4 * 5);
        for a in 0..3 {
            let from_7: Vec<_> = g3
                .face_coords_from(a, 7)
                .take(g3.num_faces(a) - 7)
                .collect();
            assert!(from_7
                .iter()
                .enumerate()
                .all(|(j, f)| *f == g3.face_coords(a, 7 + j)));
            let mut seen = vec![[0; 3]; g3.num_faces(a)];
            g3.par_for_each_face(a, &mut seen, |i, f, v| {
                assert_eq!(f, g3.face_coords(a, i));
                *v = f;
            });
            assert_eq!(
                seen[g3.num_faces(a) - 1],
                g3.face_coords(a, g3.num_faces(a) - 1)
            );
        }
    }

    #[test]
    fn interpolation_reproduces_linear_fields() {
        // A field linear in space must be interpolated exactly away from the walls.
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let mut u = MacField::zeros(&g);
            let lin = |p: &[f64]| {
                p.iter()
                    .enumerate()
                    .map(|(k, v)| (k as f64 + 1.5) * v)
                    .sum::<f64>()
            };
            for a in 0..D {
                for i in 0..g.num_faces(a) {
                    let f = g.face_coords(a, i);
                    let p: Vec<f64> = (0..D)
                        .map(|k| {
                            if k == a {
                                f[k] as f64
                            } else {
                                f[k] as f64 + 0.5
                            }
                        })
                        .collect();
                    u.comp[a][i] = lin(&p) + a as f64;
                }
            }
            let x = Vector::<D>::from_fn(|k, _| 1.3 + 0.37 * k as f64);
            let v = u.interpolate(&g, &x);
            for a in 0..D {
                assert!((v[a] - (lin(x.as_slice()) + a as f64)).abs() < 1e-12);
            }
        }
        check([6, 5]);
        check([5, 6, 7]);
    }

    /// The faces visited near flagged cells are exactly those with a flagged cell on a side,
    /// each once, with its index and coordinates; sparse flags leave whole lines out.
    #[test]
    fn the_faces_near_flagged_cells_are_visited_exactly_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D], every: usize) {
            let g = Grid::new(dims);
            let flags: Vec<bool> = (0..g.num_cells())
                .map(|c| (c * 7919) % every == 0)
                .collect();
            let near = NearCells::new(&g, flags.clone());
            for a in 0..D {
                let mut seen = vec![0u8; g.num_faces(a)];
                let mut at = vec![[0usize; D]; g.num_faces(a)];
                let mut other = vec![0u8; g.num_faces(a)];
                g.par_for_each_face_pair_near(a, &mut seen, &mut other, &near, |i, f, s, o| {
                    *s += 1;
                    *o += 1;
                    assert_eq!(g.face_index(a, f), i);
                });
                g.par_for_each_face_near(a, &mut at, &near, |_, f, v| *v = f);
                for i in 0..g.num_faces(a) {
                    let f = g.face_coords(a, i);
                    let want = g.face_cells_at(a, f).any(|c| flags[c]);
                    assert_eq!(seen[i] == 1, want, "axis {a}, face {f:?}");
                    assert_eq!(seen[i], other[i]);
                    assert!(!want || at[i] == f);
                }
            }
        }
        check([7, 5], 3);
        check([7, 5], 29);
        check([6, 4, 5], 5);
        check([6, 4, 5], 53);
        check([1, 3, 2], 2);
    }

    #[test]
    fn face_weights_sum_to_one_everywhere() {
        let g = Grid::new([4, 3, 5]);
        for x in [
            [0.0, 0.0, 0.0],
            [3.999, 2.999, 4.999],
            [0.2, 1.7, 2.5],
            [3.9, 0.1, 4.5],
        ] {
            let x = Vector::<3>::from(x);
            for a in 0..3 {
                let s: f64 = FaceStencil::new(&g, a, &x).weights().map(|(_, w)| w).sum();
                assert!((s - 1.0).abs() < 1e-12, "axis {a} at {x:?}: {s}");
            }
        }
    }

    #[test]
    fn face_stencil_has_the_tent_weights_and_stays_inside_thin_grids() {
        let g = Grid::new([4, 3]);
        let st = FaceStencil::new(&g, 0, &Vector::<2>::new(1.25, 1.75));
        // Faces of axis 0 at x = 1, 2 and y = 1.5, 2.5 (face dims [5, 3]).
        let want = [(6, 0.5625), (7, 0.1875), (11, 0.1875), (12, 0.0625)];
        assert_eq!(st.weights().collect::<Vec<_>>(), want);
        // One cell thick along y (and z): the faces repeat with weight 0, all indices valid.
        for g in [Grid::new([3, 1, 1]), Grid::new([1, 1, 1])] {
            for a in 0..3 {
                let st = FaceStencil::new(&g, a, &Vector::<3>::new(0.9, 0.3, 0.7));
                assert!(st.weights().all(|(i, _)| i < g.num_faces(a)));
                let total: f64 = st.weights().map(|(_, w)| w).sum();
                assert!((total - 1.0).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn components_are_the_member_cells_the_seeds_reach_2d_and_3d() {
        /// Members: a slab x < 2, a slab x > 4 joined to it along the last axis' first layer
        /// only when `joined`, and nothing else.
        fn check<const D: usize>(joined: bool) {
            let g = Grid::<D>::new([8; D]);
            let at = |c: usize| g.cell_coords(c);
            let bridge = |c: usize| joined && at(c)[D - 1] == 0;
            let member = |c: usize| at(c)[0] < 2 || at(c)[0] > 4 || bridge(c);
            let left = |c: usize| at(c)[0] < 2;
            let seeds = [
                g.cell_index([1; D]),
                g.cell_index([0; D]),
                g.cell_index([1; D]),
            ];
            let got = g.components_of(seeds, member);
            let want: Vec<usize> = (0..g.num_cells())
                .filter(|&c| member(c) && (joined || left(c)))
                .collect();
            assert_eq!(got, want, "D = {D}, joined = {joined}");
            assert!(g.components_of([], member).is_empty());
        }
        for joined in [false, true] {
            check::<2>(joined);
            check::<3>(joined);
        }
    }

    #[test]
    fn cell_of_floors_inside_and_refuses_outside_the_domain() {
        let below = |n: f64| n - n * f64::EPSILON;
        let g = Grid::new([4, 3]);
        assert_eq!(g.cell_of(&Vector::<2>::new(0.0, 0.0)), Some([0, 0]));
        assert_eq!(g.cell_of(&Vector::<2>::new(1.0, 2.5)), Some([1, 2]));
        assert_eq!(
            g.cell_of(&Vector::<2>::new(below(4.0), below(3.0))),
            Some([3, 2])
        );
        for x in [
            [-1e-300, 1.0],
            [4.0, 1.0],
            [1.0, 3.0],
            [f64::NAN, 1.0],
            [1.0, f64::INFINITY],
        ] {
            assert_eq!(g.cell_of(&Vector::<2>::from(x)), None, "{x:?}");
        }
        let g = Grid::new([5, 1, 7]);
        assert_eq!(
            g.cell_of(&Vector::<3>::new(4.5, 0.999, 6.0)),
            Some([4, 0, 6])
        );
        assert_eq!(
            g.cell_index_of(&Vector::<3>::new(4.5, 0.999, 6.0)),
            4 + 5 * 6
        );
        assert_eq!(g.cell_of(&Vector::<3>::new(4.5, -0.0, 7.0)), None);
    }

    #[test]
    fn points_beyond_the_faces_use_the_outermost_ones() {
        fn check<const D: usize>(dims: [usize; D], x: [f64; D]) {
            let g = Grid::new(dims);
            for a in 0..D {
                // Component `a`'s faces span [0, n] on its own axis, [1/2, n - 1/2] on the others.
                let inside = Vector::<D>::from_fn(|k, _| {
                    let n = dims[k] as f64;
                    let (lo, hi) = if k == a { (0.0, n) } else { (0.5, n - 0.5) };
                    x[k].clamp(lo, hi)
                });
                let out = FaceStencil::new(&g, a, &Vector::from(x));
                let want = FaceStencil::new(&g, a, &inside)
                    .weights()
                    .collect::<Vec<_>>();
                assert_eq!(out.weights().collect::<Vec<_>>(), want, "axis {a} at {x:?}");
            }
        }
        check([4, 3], [-2.0, 7.5]);
        check([4, 3], [9.0, -0.2]);
        check([4, 3, 5], [-1.0, 3.4, 100.0]);
        check([4, 1, 5], [4.5, 0.7, -3.0]);
        // A lost particle (NaN) reads faces inside the field, never past its end.
        let g = Grid::new([4, 3, 5]);
        for a in 0..3 {
            let st = FaceStencil::new(&g, a, &Vector::<3>::repeat(f64::NAN));
            assert!(st.weights().all(|(i, _)| i < g.num_faces(a)));
        }
    }

    #[test]
    fn a_point_located_once_gives_every_component_its_own_stencil() {
        fn check<const D: usize>(dims: [usize; D], points: &[[f64; D]]) {
            let g = Grid::new(dims);
            for x in points.iter().map(|x| Vector::<D>::from(*x)) {
                let at = FacePoint::new(&g, &x);
                for a in 0..D {
                    let (one, all) = (FaceStencil::new(&g, a, &x), FaceStencil::at(&g, &at, a));
                    let (one, all): (Vec<_>, Vec<_>) =
                        (one.weights().collect(), all.weights().collect());
                    assert_eq!(one, all, "axis {a} at {x:?} in {dims:?}");
                }
            }
        }
        let in_2d = [[0.0, 0.0], [3.999, 2.999], [0.2, 1.7], [-0.3, 9.0]];
        check([4, 3], &in_2d);
        check([1, 5], &in_2d);
        let in_3d = [
            [0.0, 0.0, 0.0],
            [3.999, 2.999, 4.999],
            [0.2, 1.7, 2.5],
            [3.9, -0.1, 7.5],
        ];
        check([4, 3, 5], &in_3d);
        check([3, 1, 1], &in_3d);
    }

    #[test]
    fn closest_in_cell_moves_only_the_components_outside_the_cell() {
        let g = Grid::new([4, 4]);
        // Outside along x: to the wall, margin inside; inside along y: kept, even near the wall.
        let p = g.closest_in_cell(&Vector::<2>::new(3.7, 0.005), [1, 0], 0.01);
        assert_eq!(p, Vector::<2>::new(1.99, 0.005));
        let p = g.closest_in_cell(&Vector::<2>::new(0.2, 0.999), [1, 0], 0.01);
        assert_eq!(p, Vector::<2>::new(1.01, 0.999));
        // On a face counts as outside (|v_k| >= 0.5); a point inside is its own closest point.
        let g3 = Grid::new([4, 4, 4]);
        let p = g3.closest_in_cell(&Vector::<3>::new(2.0, 1.995, 1.0), [1, 1, 1], 0.01);
        assert_eq!(p, Vector::<3>::new(1.99, 1.995, 1.01));
        let q = Vector::<3>::new(1.001, 1.5, 1.999);
        assert_eq!(g3.closest_in_cell(&q, [1, 1, 1], 0.01), q);
        assert_eq!(g.moore_neighbors([0, 0]).count(), 3);
        assert_eq!(Grid::new([4, 4, 4]).moore_neighbors([1, 1, 1]).count(), 26);
    }
}
