//! The active part of the grid: where a step's grid passes work, so that their cost follows
//! the liquid rather than the box (at 300^3 a drop and its pool fill a tenth of the cells).
//!
//! **Storage: dense arrays, run-length active set.** Every field stays a dense array indexed
//! as [`Grid`] indexes it; what is sparse is the set of entries a pass visits: per line of
//! cells along axis 0, one span `[lo, hi)` of active cells (the hull of the line's active
//! cells), as in the run-length encoded grids of Houston et al. 2006 ("Hierarchical RLE level
//! set", ACM TOG 25(1)). A line is contiguous in memory, so a pass walks a few long runs, and
//! pages the liquid never reaches are never touched: a fresh zeroed field costs memory only
//! where it is written. See docs/architecture.md, "Active spans", for why this and not tiles.

use super::{max_abs, nan_max, Cell, Grid, MacField, NearCells, Vector};
use rayon::prelude::*;
use std::ops::Range;

/// Lines per task of a parallel pass (a line is tens to hundreds of entries).
const LINE_GRAIN: usize = 64;

/// An empty span: the identity of [`hull`].
pub(crate) const EMPTY: [u32; 2] = [u32::MAX, 0];

/// The smallest span holding both.
pub(crate) fn hull(a: [u32; 2], b: [u32; 2]) -> [u32; 2] {
    [a[0].min(b[0]), a[1].max(b[1])]
}

/// Per line of cells along axis 0, the hull of its cells where `flag` holds, [`EMPTY`] where
/// none does (one pass over every cell).
pub(crate) fn line_hulls<const D: usize>(
    grid: &Grid<D>,
    flag: impl Fn(usize) -> bool + Sync,
) -> Vec<[u32; 2]> {
    let n0 = grid.dims[0];
    (0..grid.num_cells() / n0)
        .into_par_iter()
        .with_min_len(LINE_GRAIN)
        .map(|l| {
            let line = l * n0..(l + 1) * n0;
            match line.clone().position(&flag) {
                None => EMPTY,
                Some(lo) => [lo as u32, (n0 - line.rev().position(&flag).unwrap()) as u32],
            }
        })
        .collect()
}

/// Each line's span widened by `margin` cells along axis 0, then made the hull of the spans of
/// the lines within `margin` along each other axis, one axis at a time (`spans` has one entry
/// per line of cells along axis 0 of a grid of `dims`).
pub(crate) fn dilate<const D: usize>(
    dims: &[usize; D],
    mut spans: Vec<[u32; 2]>,
    margin: usize,
) -> Vec<[u32; 2]> {
    let n0 = dims[0];
    for s in spans.iter_mut().filter(|s| s[0] < s[1]) {
        *s = [
            s[0].saturating_sub(margin as u32),
            (s[1] as usize + margin).min(n0) as u32,
        ];
    }
    let line_stride = super::strides(dims).map(|s| s / n0);
    for a in 1..D {
        let (stride, len) = (line_stride[a], dims[a]);
        spans = (0..spans.len())
            .into_par_iter()
            .with_min_len(LINE_GRAIN)
            .map(|l| {
                let at = l / stride % len;
                let first = l - at.min(margin) * stride;
                let last = l + (len - 1 - at).min(margin) * stride;
                (first..=last)
                    .step_by(stride)
                    .fold(EMPTY, |s, k| hull(s, spans[k]))
            })
            .collect();
    }
    spans
}

/// Per line of cells along axis 0 of a grid of `dims`, the hull of the cells of `cells` (each
/// cell's coordinates, inside the grid) in it, [`EMPTY`] where there is none. In parallel: a
/// few pieces of the cells each find their spans, then the pieces' spans are joined.
pub(crate) fn line_spans<const D: usize>(
    dims: &[usize; D],
    cells: impl IndexedParallelIterator<Item = [usize; D]>,
) -> Vec<[u32; 2]> {
    let n0 = dims[0];
    let lines = dims.iter().product::<usize>() / n0;
    let line_stride = super::strides(dims).map(|s| s / n0);
    let pieces = 4 * rayon::current_num_threads();
    let per_piece = cells.len().div_ceil(pieces).max(crate::PAR_GRAIN_PARTICLES);
    (cells.with_min_len(per_piece))
        .fold(
            || vec![EMPTY; lines],
            |mut spans, c| {
                let line: usize = (1..D).map(|k| c[k] * line_stride[k]).sum();
                spans[line] = hull(spans[line], [c[0] as u32, c[0] as u32 + 1]);
                spans
            },
        )
        .reduce_with(|mut a, b| {
            a.iter_mut().zip(b).for_each(|(s, t)| *s = hull(*s, t));
            a
        })
        .unwrap_or_else(|| vec![EMPTY; lines])
}

/// The active cells of a grid and the faces beside them, as ascending index ranges.
#[derive(Clone, Debug, PartialEq)]
pub struct Active<const D: usize> {
    /// One range of cell indices per line of cells that holds any active cell.
    cells: Vec<Range<usize>>,
    /// Per component, one range of face indices per line of faces beside an active cell:
    /// the hull of the faces of its active cells on either side.
    faces: [Vec<Range<usize>>; D],
}

impl<const D: usize> Active<D> {
    /// Every cell active.
    pub fn all(grid: &Grid<D>) -> Self {
        let n0 = grid.dims[0] as u32;
        Self::from_spans(grid, vec![[0, n0]; grid.num_cells() / n0 as usize])
    }

    /// The cells within `margin` cells of a cell where `seed` holds (along every axis at
    /// once: the cube of side `2 margin + 1` around each), each line's as one span.
    pub fn around(grid: &Grid<D>, seed: impl Fn(usize) -> bool + Sync, margin: usize) -> Self {
        Self::around_spans(grid, line_hulls(grid, seed), margin)
    }

    /// As [`Self::around`], from each line's hull of its seeds (one span per line of cells
    /// along axis 0, [`EMPTY`] where it has none).
    pub(crate) fn around_spans(grid: &Grid<D>, seeds: Vec<[u32; 2]>, margin: usize) -> Self {
        Self::from_spans(grid, dilate(&grid.dims, seeds, margin))
    }

    /// As [`Self::around`] with the cells that hold one of the points `pos` (inside the
    /// domain) as seeds. In parallel: a few pieces of the points each find their spans, then
    /// the pieces' spans are joined.
    pub fn around_points<'p>(
        grid: &Grid<D>,
        pos: impl IndexedParallelIterator<Item = &'p Vector<D>>,
        margin: usize,
    ) -> Self {
        let cells = pos.map(|x| {
            grid.cell_of(x)
                .unwrap_or_else(|| panic!("point {:?} is outside the domain", x.as_slice()))
        });
        Self::around_spans(grid, line_spans(&grid.dims, cells), margin)
    }

    /// The ranges from one span per line of cells.
    fn from_spans(grid: &Grid<D>, spans: Vec<[u32; 2]>) -> Self {
        let n0 = grid.dims[0];
        let ranges = |spans: &mut dyn Iterator<Item = (usize, [u32; 2])>| {
            spans
                .filter(|(_, s)| s[0] < s[1])
                .map(|(start, s)| start + s[0] as usize..start + s[1] as usize)
                .collect()
        };
        let cells = ranges(&mut spans.iter().enumerate().map(|(l, &s)| (l * n0, s)));
        let faces = std::array::from_fn(|a| {
            let len = grid.face_dims(a)[0];
            let lines = grid.num_faces(a) / len;
            let span = |l: usize| {
                if a == 0 {
                    let [lo, hi] = spans[l];
                    return if lo < hi { [lo, hi + 1] } else { EMPTY };
                }
                // The lines of cells below and above a line of faces normal to `a`.
                let f = grid.face_coords(a, l * len);
                let stride = grid.cell_stride(a) / n0;
                let above = (f[a] < grid.dims[a]).then(|| grid.cell_index(f) / n0);
                let below = (f[a] > 0).then(|| grid.cell_index(f) / n0 - stride);
                let above = above.map_or(EMPTY, |k| spans[k]);
                below.map_or(above, |k| hull(above, spans[k]))
            };
            ranges(&mut (0..lines).map(|l| (l * len, span(l))))
        });
        Active { cells, faces }
    }

    /// The active cells, one ascending index range per line.
    pub fn cells(&self) -> &[Range<usize>] {
        &self.cells
    }

    /// The faces of component `axis` beside an active cell, one ascending range per line.
    pub fn faces(&self, axis: usize) -> &[Range<usize>] {
        &self.faces[axis]
    }

    /// The cells of the set where `flag` holds, with their lines: a [`NearCells`] whose flags
    /// off the set are false and never asked for (so their pages are never touched). For the
    /// cells of markings the set was built around, the same as [`NearCells::new`] of all flags.
    pub fn near_cells(&self, grid: &Grid<D>, flag: impl Fn(usize) -> bool + Sync) -> NearCells {
        let n0 = grid.dims[0];
        let cells = self.flags(grid, flag);
        let mut lines = vec![false; grid.num_cells() / n0];
        for r in &self.cells {
            lines[r.start / n0] = cells[r.clone()].contains(&true);
        }
        NearCells { cells, lines }
    }

    /// `flag` of every cell of the set, false off it (one entry per cell of the grid; the
    /// pages off the set are never touched).
    pub fn flags(&self, grid: &Grid<D>, flag: impl Fn(usize) -> bool + Sync) -> Vec<bool> {
        let mut flags = vec![false; grid.num_cells()];
        par_runs(&self.cells, &mut flags).for_each(|(r, run)| {
            r.zip(run).for_each(|(c, v)| *v = flag(c));
        });
        flags
    }

    /// The active cells numbered densely in index order, for per-cell scratch arrays as long
    /// as the set rather than the grid.
    pub fn numbers(&self, grid: &Grid<D>) -> CellNumbers {
        let n0 = grid.dims[0];
        let mut span = vec![(0, 0, 0); grid.num_cells() / n0];
        let mut len = 0;
        for r in &self.cells {
            span[r.start / n0] = (r.start % n0, r.end - r.start, len);
            len += r.len();
        }
        let line_strides = (1..D).map(|k| grid.cell_stride(k) / n0).collect();
        CellNumbers {
            n0,
            line_strides,
            span,
            len,
        }
    }

    /// Every active cell's index, ascending.
    pub fn each_cell(&self) -> impl Iterator<Item = usize> + '_ {
        self.cells.iter().flat_map(|r| r.clone())
    }

    /// The first active cell (in index order) where `f` holds, whatever the thread count: the
    /// lines in parallel, each searched by a plain loop (rayon's per-item `find_first` costs
    /// several times the reads).
    pub fn first_cell(&self, f: impl Fn(usize) -> bool + Sync) -> Option<usize> {
        (self.cells.par_iter().with_min_len(LINE_GRAIN))
            .find_map_first(|r| r.clone().find(|&c| f(c)))
    }

    /// How many active cells satisfy `f`, the lines in parallel.
    pub fn count_cells(&self, f: impl Fn(usize) -> bool + Sync) -> usize {
        let lines = self.cells.par_iter().with_min_len(LINE_GRAIN);
        lines.map(|r| r.clone().filter(|&c| f(c)).count()).sum()
    }

    /// How many cells are active.
    pub fn num_cells(&self) -> usize {
        self.cells.iter().map(|r| r.len()).sum()
    }

    /// How many faces of component `axis` are active.
    pub fn num_faces(&self, axis: usize) -> usize {
        self.faces[axis].iter().map(|r| r.len()).sum()
    }

    /// `f(face_index, face_coords, value)` for every active face of component `axis`, with
    /// its entry of `values` (one per face of the grid), in parallel over lines.
    pub fn par_for_each_face<T: Send>(
        &self,
        grid: &Grid<D>,
        axis: usize,
        values: &mut [T],
        f: impl Fn(usize, Cell<D>, &mut T) + Sync,
    ) {
        assert_eq!(values.len(), grid.num_faces(axis));
        par_runs(&self.faces[axis], values).for_each(|(r, run)| {
            let coords = grid.face_coords_from(axis, r.start);
            for ((i, v), c) in r.zip(run).zip(coords) {
                f(i, c, v);
            }
        });
    }
}

impl<const D: usize> Active<D> {
    /// `u` on the active faces, zero elsewhere.
    pub fn copy(&self, u: &MacField<D>) -> MacField<D> {
        let comp = std::array::from_fn(|a| {
            let mut out = vec![0.0; u.comp[a].len()];
            par_runs(&self.faces[a], &mut out)
                .for_each(|(r, run)| run.copy_from_slice(&u.comp[a][r]));
            out
        });
        MacField { comp }
    }

    /// The largest absolute value of `u` over the active faces; NaN if any is NaN.
    pub fn max_abs(&self, u: &MacField<D>) -> f64 {
        (0..D)
            .map(|a| {
                (self.faces[a].par_iter().with_min_len(LINE_GRAIN))
                    .map(|r| max_abs(&u.comp[a][r.clone()]))
                    .reduce(|| 0.0, nan_max)
            })
            .fold(0.0, nan_max)
    }
}

/// The dense numbers of an [`Active`] set's cells ([`Active::numbers`]).
pub struct CellNumbers {
    n0: usize,
    /// Per axis from 1 on, the step between lines of cells along it.
    line_strides: Vec<usize>,
    /// Per line of cells: its span's first cell along axis 0, its length and the number of
    /// that first cell.
    span: Vec<(usize, usize, usize)>,
    len: usize,
}

impl CellNumbers {
    /// How many cells are numbered.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The number of cell `c`, if it is active.
    pub fn get(&self, c: usize) -> Option<usize> {
        self.in_line(c / self.n0, c % self.n0)
    }

    /// The numbered cells, in the order of their numbers.
    pub fn cells(&self) -> impl Iterator<Item = usize> + '_ {
        let n0 = self.n0;
        (self.span.iter().enumerate())
            .flat_map(move |(l, &(lo, len, _))| l * n0 + lo..l * n0 + lo + len)
    }

    /// [`Self::get`] of the cell at coordinates `c`, without a division.
    pub fn at<const D: usize>(&self, c: Cell<D>) -> Option<usize> {
        let line = (1..D).map(|k| c[k] * self.line_strides[k - 1]).sum();
        self.in_line(line, c[0])
    }

    fn in_line(&self, line: usize, x: usize) -> Option<usize> {
        let (lo, len, first) = self.span[line];
        let at = x.wrapping_sub(lo);
        (at < len).then_some(first + at)
    }
}

/// The runs of `values` at `ranges` (ascending, disjoint), with their ranges, as a parallel
/// iterator: each run is a slice of its own, so that a pass can write them all at once.
pub fn par_runs<'a, T: Send>(
    ranges: &'a [Range<usize>],
    mut values: &'a mut [T],
) -> impl IndexedParallelIterator<Item = (Range<usize>, &'a mut [T])> {
    let mut runs = Vec::with_capacity(ranges.len());
    let mut at = 0;
    for r in ranges {
        let (_, rest) = std::mem::take(&mut values).split_at_mut(r.start - at);
        let (run, rest) = rest.split_at_mut(r.len());
        runs.push(run);
        (values, at) = (rest, r.end);
    }
    (ranges.par_iter().cloned())
        .zip(runs)
        .with_min_len(LINE_GRAIN)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Whether cell `c` lies within `margin` of a seed along every axis, by brute force.
    fn near_seed<const D: usize>(g: &Grid<D>, seed: &[bool], c: Cell<D>, margin: usize) -> bool {
        (0..g.num_cells()).any(|s| {
            let sc = g.cell_coords(s);
            seed[s] && (0..D).all(|k| sc[k].abs_diff(c[k]) <= margin)
        })
    }

    /// A grid of `dims`, each cell a seed with probability `p`, and the set around the seeds
    /// within `margin`.
    fn random_set<const D: usize>(
        dims: [usize; D],
        p: f64,
        margin: usize,
        rng_seed: u64,
    ) -> (Grid<D>, Vec<bool>, Active<D>) {
        let g = Grid::new(dims);
        let mut rng = rand::rngs::StdRng::seed_from_u64(rng_seed);
        let seed: Vec<bool> = (0..g.num_cells()).map(|_| rng.random_bool(p)).collect();
        let active = Active::around(&g, |c| seed[c], margin);
        (g, seed, active)
    }

    /// The active set holds every cell near a seed, each line's active cells are the hull of
    /// its cells near a seed, and the faces are the hull of the faces of the active cells on
    /// either side; checked against brute force on random seeds.
    fn check<const D: usize>(dims: [usize; D], seeds: f64, margin: usize, rng_seed: u64) {
        let (g, seed, active) = random_set(dims, seeds, margin, rng_seed);
        let mut is = vec![false; g.num_cells()];
        active.each_cell().for_each(|c| is[c] = true);
        let n0 = dims[0];
        for (l, line) in is.chunks(n0).enumerate() {
            let near: Vec<usize> = (0..n0)
                .filter(|&x| near_seed(&g, &seed, g.cell_coords(l * n0 + x), margin))
                .collect();
            let expect = |x: usize| {
                near.first()
                    .is_some_and(|&lo| lo <= x && x <= near[near.len() - 1])
            };
            assert!(
                (0..n0).all(|x| line[x] == expect(x)),
                "line {l} of {dims:?}"
            );
        }
        for a in 0..D {
            let mut on = vec![false; g.num_faces(a)];
            active.par_for_each_face(&g, a, &mut on, |i, f, v| {
                assert_eq!(g.face_coords(a, i), f);
                *v = true;
            });
            assert_eq!(on.iter().filter(|&&v| v).count(), active.num_faces(a));
            for (i, &v) in on.iter().enumerate() {
                let beside = g.face_cells(a, i).any(|c| is[c]);
                // A face beside an active cell is active; an active face lies between two
                // active faces of its line, or is beside an active cell.
                assert!(!beside || v, "face {i} of component {a}");
            }
            for r in active.faces(a) {
                let ends = [r.start, r.end - 1];
                assert!(ends.iter().all(|&i| g.face_cells(a, i).any(|c| is[c])));
            }
        }
    }

    #[test]
    fn the_active_set_is_the_hull_of_each_line_near_a_seed_2d_and_3d() {
        for (seed, (p, m)) in [(0.0, 1), (0.002, 0), (0.01, 1), (0.05, 2), (1.0, 3)]
            .into_iter()
            .enumerate()
        {
            check([13, 9], p, m, seed as u64);
            check([7, 9, 6], p, m, 10 + seed as u64);
        }
    }

    #[test]
    fn around_points_seeds_the_points_cells_2d_and_3d() {
        fn check_points<const D: usize>(dims: [usize; D], seed: u64) {
            let g = Grid::new(dims);
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let pos: Vec<Vector<D>> = (0..5)
                .map(|_| Vector::<D>::from_fn(|k, _| rng.random_range(0.0..dims[k] as f64)))
                .collect();
            let cells: Vec<usize> = pos.iter().map(|x| g.cell_index_of(x)).collect();
            for margin in [0, 1, 3] {
                let by_cells = Active::around(&g, |c| cells.contains(&c), margin);
                assert_eq!(Active::around_points(&g, pos.par_iter(), margin), by_cells);
            }
        }
        check_points([11, 7], 1);
        check_points([6, 5, 9], 2);
    }

    /// Built on a set that holds every flagged cell, the near cells are those of all flags,
    /// and off the set nothing is flagged.
    #[test]
    fn near_cells_on_the_set_are_those_of_every_cell_2d_and_3d() {
        fn check_near<const D: usize>(dims: [usize; D], seed: u64) {
            let (g, flags, active) = random_set(dims, 0.03, 0, seed);
            let near = active.near_cells(&g, |c| flags[c]);
            let whole = NearCells::new(&g, flags.clone());
            assert!(whole.lines.contains(&false) && whole.lines.contains(&true));
            assert_eq!((&near.cells, &near.lines), (&whole.cells, &whole.lines));
            // Every cell of the set is asked, and no other.
            let asked = active.flags(&g, |_| true);
            assert!((0..g.num_cells()).all(|c| asked[c] == active.each_cell().any(|a| a == c)));
        }
        check_near([23, 9], 5);
        check_near([8, 7, 9], 6);
    }

    /// The numbers count the active cells in index order, and only them.
    #[test]
    fn numbers_count_the_active_cells_in_order_2d_and_3d() {
        fn check_numbers<const D: usize>(dims: [usize; D], seed: u64) {
            let (g, _, active) = random_set(dims, 0.02, 1, seed);
            let numbers = active.numbers(&g);
            let listed: Vec<usize> = active.each_cell().collect();
            assert!(!listed.is_empty() && listed.len() < g.num_cells());
            assert_eq!(numbers.len(), listed.len());
            let mut next = 0;
            for c in 0..g.num_cells() {
                let expect = listed.contains(&c).then(|| {
                    next += 1;
                    next - 1
                });
                assert_eq!(numbers.get(c), expect, "cell {c} of {dims:?}");
                assert_eq!(numbers.at(g.cell_coords(c)), expect, "cell {c} of {dims:?}");
            }
            assert!(numbers.cells().eq(listed));
        }
        check_numbers([17, 9], 3);
        check_numbers([6, 7, 9], 4);
    }

    #[test]
    fn all_is_every_cell_and_face_2d_and_3d() {
        fn check_all<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let all = Active::all(&g);
            assert_eq!(all, Active::around(&g, |_| true, 0));
            assert_eq!(all.num_cells(), g.num_cells());
            (0..D).for_each(|a| assert_eq!(all.num_faces(a), g.num_faces(a)));
            let numbers = all.numbers(&g);
            assert_eq!(numbers.len(), g.num_cells());
            assert!((0..g.num_cells()).all(|c| numbers.get(c) == Some(c)));
        }
        check_all([5, 4]);
        check_all([3, 5, 4]);
    }
}
