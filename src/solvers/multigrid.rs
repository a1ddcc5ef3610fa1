//! A geometric multigrid V-cycle as CG's preconditioner for the pressure matrix: MGPCG after
//! McAdams, Sifakis and Teran 2010, "A parallel multigrid Poisson solver for fluids simulation
//! on large grids" (below: McAdams). It knows no fluid, only a grid whose cells are classed.
//!
//! **The system.** [`Multigrid::new`] takes the grid's dimensions and one [`CellClass`] per
//! cell (linear order, axis 0 fastest, as `crate::grid::Grid`). Its rows are the
//! [`CellClass::Unknown`] cells in ascending cell order, and the matrix is the (2D+1)-point
//! negative Laplacian in unit cells: `-1` between neighbouring unknowns, and on the diagonal
//! the number of neighbours that are unknown or [`CellClass::Dirichlet`] (a known zero);
//! [`CellClass::Neumann`] cells and the outside of the grid add nothing. This is exactly the
//! matrix `crate::stages::pressure::Poisson` builds (empty cells Dirichlet, solid cells Neumann),
//! so the finest level smooths the very system CG solves. The classes, rather than the
//! matrix, are the input because coarsening needs them: a matrix row tells how many
//! neighbours are Dirichlet, not which.
//!
//! **Coarsening.** Level `l + 1` halves every axis (rounding up); a coarse cell is
//! Dirichlet if any of its `2^D` children is, else an unknown if any child is, else Neumann.
//! The free surface thus stays a known zero on every level, moved inward by at most a coarse
//! cell, and fluid rows under such a cell take no coarse correction from it (the smoother
//! handles them). The other order (unknown first) moves the surface outward instead, so the
//! coarse problem sees a deeper liquid than the fine one and over-corrects near the surface:
//! measured 2026-11-26 on falling-obstacle-3d `--res 200`, it took 19-20 iterations against
//! 13 with Dirichlet first (dam-3d 100^3: 14 against 11; 64^3 12 against 11). A closed region
//! keeps its coarse image, except where a coarse cell also covers an empty cell across a wall.
//! Faces are coarsened too: a coarse face is open if any
//! face of the finest grid within it joins two cells that are not Neumann, and closed
//! otherwise (a solid wall all along it). Without this, a wall one cell thick between two
//! parts of a winding one-cell channel vanishes inside the coarse cells and the coarse
//! problem short-circuits the channel (a 64 x 64 serpentine: 469 iterations to 1e-12; with
//! closed faces kept, 157, both with unknown-first coarsening; the dam problems do not
//! change). Coarsening stops once a level has
//! at most [`COARSEST_ROWS`] rows, or earlier where the next level would lose the liquid's
//! image ([`loses_the_liquid`]: it would keep under a quarter of the rows that halving every
//! axis keeps, as when a pool's last layer is thinner than two coarse cells), if that level's
//! dense factor is cheap beside the finest level. Otherwise the layer's smoothest modes got no
//! coarse correction at all: a pool 15 cells deep on 160 x 160 cells took 11 PCG iterations
//! where one 16 deep took 9 (its 400-row layer on level 3 vanished on level 4).
//!
//! **Coarse operators: rediscretisation**, as McAdams, rather than Galerkin `R A P`: the
//! coarse matrix is the same (2D+1)-point stencil on the coarse classes, across open faces
//! only, so every level keeps the finest level's storage and smoother, and stays symmetric
//! positive semi-definite by construction. Galerkin with the trilinear transfers below would
//! give 27-point stencils in 3D (three times the storage and work per row) for a coarse
//! correction that is only an approximation either way. The stencil is scaled by
//! `2^{(D-2) l}`: with `R = P^T` (which sums `2^D` fine residuals per coarse cell) and
//! unit-cell stencils, `R A P` of a smooth function is `2^D / 4` times the coarse stencil, the
//! 4 being the coarse cell's squared width.
//! A coarse row's Dirichlet neighbour is weighted by its distance, though: `1 / theta` on the
//! diagonal, `theta` the distance in coarse cells from the row's centre to where the finest
//! level's zero lies behind that face ([`Cells::dirichlet_weight`], a ghost-fluid boundary).
//! Dirichlet-first coarsening puts the coarse zero nearer than the fine one; weighting it so
//! cut the iterations by up to a quarter (half-full tank 128^3: 12 to 9; drop-3d 200^3: 11 to
//! 9; drop-3d 300^3: 14 to 13; falling-obstacle-3d 100^3: 12 to 12), and it changes only
//! diagonals, so every coarse operator stays symmetric and positive semi-definite.
//!
//! **Cells cut by the grid's walls.** Where an axis's cell count is not divisible by a level's
//! side, the level's last cell along it reaches past the grid: only a share `e < 1` of it
//! holds finest cells. Such a row's faces are weighted as a finite volume
//! ([`Operator::face_weight`]): a face's coupling is its area (the product of the cell's
//! shares across it) over the distance between the two cells' centroids (`(1 + e) / 2`
//! between the last two cells), a Dirichlet neighbour's distance weight is measured from the
//! centroid and times the face's area, and the diagonal is their sum; every other row keeps
//! its whole counts and the same storage. Treating the cut cell as whole put its centroid
//! half a cut too far, and cost up to half again the iterations: the half-full tank at 65^3
//! took 14 PCG iterations against 9 at 64^3 (10 with the weights), falling-obstacle-3d at
//! 100^3 12 (9), large-obstacle-3d at 75^3 11 (9), drop-3d at 100^3 10 (9). The weights are
//! the same seen from either side of a face, so every coarse operator stays symmetric.
//!
//! **Transfers.** Prolongation `P` is trilinear (bilinear in 2D) interpolation of
//! cell-centred values, as McAdams: a fine cell takes 3/4 of its parent and 1/4 of the
//! parent's neighbour on its side, per axis. Of the `2^D` coarse cells so weighted, an
//! unknown gives its value, a Neumann cell, the outside, or a cell behind a closed face of
//! the parent the parent's value (the mirror image a no-flux wall implies), so that `P` maps
//! a constant to a constant away from Dirichlet cells; and a Dirichlet cell next to rows
//! gives the ghost value the coarse operator's distance weight implies ([`Ghosts`]): each
//! such row's value extrapolated linearly to the zero at distance `theta` behind that face,
//! `x (1 - 1 / theta)`, averaged over the rows it borders (other Dirichlet cells give zero).
//! Giving zero there instead put the coarse surface's zero at the coarse cell's centre, up to
//! a coarse cell nearer than the fine one, so that the fine liquid under a Dirichlet coarse
//! cell took a quarter of the correction below it where a linear profile asks for about a
//! half: a pool 15 cells deep took 12 PCG iterations where one 16 deep took 9 (both 9 now),
//! drop-3d at 300^3 13 (9 with the early stop above). `R = P^T` restricts into those
//! cells too and hands each one's sum back to its rows with the same weights, so the
//! V-cycle stays symmetric.
//! Restriction is exactly `R = P^T`, evaluated as a gather over the `4^D` fine cells that may
//! interpolate from each coarse cell. Both read their neighbours' values from the vector
//! spread over the level's grid (zero off the rows), not through a row lookup per cell; and
//! where every row of a coarse cell's block moves freely (the bulk of a large pool),
//! restriction is the plain full-weighting sum over that grid, summed separably by axis
//! ([`full_weighting`]). Together this took the two transfers from 84 to 56 ms per V-cycle on
//! the 4 M rows of falling-obstacle-3d `--res 200`; the separable sum took restriction from 301
//! to 187 ms per solve at drop-3d 300^3.
//!
//! **Smoother**: red-black Gauss-Seidel rather than McAdams' damped Jacobi: it smooths better per
//! sweep, needs no damping factor, and each half-sweep is just as parallel, since a colour couples
//! only to the other. Each level stores its red rows first, then its black rows, so a half-sweep
//! writes one slice while reading the other ([`SWEEPS`] each way). Pre-smoothing runs red then
//! black, post-smoothing black then red: the post-smoother is the pre-smoother's transpose. A row
//! with no coupling at all (a single cell among Neumann cells, zero diagonal) is smoothed with the
//! level's scale in place of its diagonal, as a correction `x_i += r_i / scale`: overwriting it
//! instead would drop the coarse correction there on the way up but not on the way down, and break
//! the symmetry.
//!
//! **Work skipped** (exact in exact arithmetic, so the operator and the argument below are
//! unchanged): after pre-smoothing ends with a black half-sweep, each coupled black row's
//! residual is zero, so the residual is computed on the red rows only; post-smoothing begins
//! by overwriting each coupled black row's `x` without reading it, so prolongation adds the
//! coarse correction on the red rows only; and the first red half-sweep from `x = 0` reads
//! no neighbour. Tried and not kept (2026-11-29, docs/benchmarks/pressure.md): McAdams'
//! boundary smoothing (extra sweeps on the rows within two steps of a Dirichlet or Neumann
//! neighbour) and one sweep each way instead of two, alone or with that band: none moved
//! fewer bytes per solve by more than a few percent.
//!
//! **CG in the finest level's order**: [`solve`] takes the right-hand side into the finest
//! level's row order once per solve and runs CG there, with that level's operator (the
//! system's matrix) as CG's matrix ([`Preconditioned`]), so that a V-cycle reads CG's residual
//! and writes its `z` in place: no permutation per iteration.
//!
//! **Coarsest level**: an exact solve by a dense Cholesky factor. A connected part of it
//! with no Dirichlet neighbour (a closed region: its block is singular, with the constants
//! as null space) gets `(s / |K|) 1_K 1_K^T` added, `s` the level's scale: the factor then
//! inverts the pseudo-inverse plus a constant on `K`, which `P` carries to a constant on the
//! fine closed region, the fine matrix's own null space. The right-hand side's mean over a
//! closed region is removed by the caller (as for MIC(0)); `P^T` keeps it zero on the
//! coarse image (`1^T P^T r = (P 1)^T r`), and where it is not (a closed coarse region whose
//! fine children reach a Dirichlet cell) the rank-one term keeps the solve bounded.
//!
//! **Symmetry and definiteness** (the conditions of Tatebe 1993, "The multigrid
//! preconditioned conjugate gradient method"). Let `S` be one forward sweep, `S^-1 = D' + L`
//! in red-black order (`D'` the smoothing diagonal, `L` the black-to-red couplings), so the
//! backward sweep is `S^T`. The V-cycle on level `l` is
//! `B_l = S_bar + (I - S^T A) P B_{l+1} P^T (I - A S)`, with
//! `S_bar = S + S^T - S^T A S = S^T (2D' - D) S`. It is symmetric because the post-smoother
//! is the pre-smoother's transpose and `R = P^T`; positive definite because `2D' - D` is
//! (it is `D` on coupled rows, `2 scale` on uncoupled ones) and `S` is invertible, while the
//! second term is semi-definite whenever `B_{l+1}` is. More sweeps nest the same way (the
//! inner sweeps take the place of the coarse correction), and the coarsest `B` is the
//! inverse of a positive definite matrix. So the V-cycle is symmetric positive definite even
//! for singular (closed) systems, and CG stays valid.

use crate::grid::active::{dilate, line_spans, par_runs};
use crate::solvers::pcg::{self, PcgSettings, PcgStats, Preconditioned, StencilMatrix};
use crate::solvers::NONE;
use crate::PAR_GRAIN;
use rayon::prelude::*;
use std::borrow::Cow;
use std::ops::Range;

/// What a cell is to the system.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellClass {
    /// A row of the system (a fluid cell).
    Unknown,
    /// A known zero next to the unknowns (an empty cell at the free surface).
    Dirichlet,
    /// No coupling (a solid cell; the outside of the grid counts as one).
    Neumann,
}

/// The system as [`Multigrid::new`] takes it: its grid, every cell's class, and its rows
/// and matrix.
pub struct Finest<'a, const D: usize> {
    pub dims: [usize; D],
    /// The class of any cell of the grid.
    pub class: &'a (dyn Fn(usize) -> CellClass + Sync),
    /// The [`CellClass::Unknown`] cells, ascending: the system's rows in order.
    pub unknowns: &'a [usize],
    /// The system's matrix on `class` (see the module doc).
    pub matrix: &'a StencilMatrix<D>,
}

/// The rows at which coarsening stops (unless it stops earlier, [`loses_the_liquid`]): the
/// coarsest level's dense Cholesky factor costs `n^3 / 6` operations per solve and each
/// application `2 n^2`, well below one fine-level sweep.
pub const COARSEST_ROWS: usize = 256;

/// Operations per finest row that the coarsest level's dense factor may cost (`n^3 / 6` for
/// `n` rows) when coarsening stops early ([`loses_the_liquid`]), once per solve: about 4% of
/// a 9-iteration solve, whose V-cycles spend about 165 instructions a finest row each
/// (docs/benchmarks/pressure.md). A pool 15 cells deep on 160 x 160 cells stops at 400 rows,
/// 28 operations a finest row: 2.3-2.7 ms of a 147 ms pressure stage.
const DENSE_OPS_PER_ROW: usize = 64;

/// Whether coarsening should stop at a level of `rows` rows because the next keeps only
/// `next` of them: fewer than `1 / 2^(D + 1)`, a quarter of what halving every axis keeps, so
/// that liquid thinner than two of this level's cells (a shallow pool's last layer, a small
/// drop) has no image below (Dirichlet-first coarsening makes any coarse cell that reaches
/// air a known zero). The level's smoothest modes would then get no coarse correction; as
/// the coarsest level they are solved exactly, if its dense factor costs at most
/// [`DENSE_OPS_PER_ROW`] operations per finest row (`finest` rows).
fn loses_the_liquid<const D: usize>(rows: usize, next: usize, finest: usize) -> bool {
    next << (D + 1) < rows && rows.pow(3) / 6 <= DENSE_OPS_PER_ROW * finest
}

/// The fewest rows a parallel loop over a level's rows gives one task: a row's stencil
/// (seven or eight gathers) is several vector entries' work, so half of [`PAR_GRAIN`]
/// ([`PAR_GRAIN`] itself left each half-sweep of a 100^3 dam's 54,000 rows on one thread:
/// about 7 ms per V-cycle there against 5; a quarter slowed 64^3, whose 15,000 rows do
/// better on one thread); restriction, 64 gathers per coarse row, a quarter of that.
const ROW_GRAIN: usize = PAR_GRAIN / 2;

/// The unit of a stencil's diagonal ([`Stencil::count`]): an eighth of the level's scale, so
/// that a coarse row's Dirichlet neighbour can weigh `1 / theta` ([`Cells::dirichlet_weight`])
/// while the stencil stays one byte; every finest row's diagonal is a whole count.
const EIGHTHS: u8 = 8;

/// The largest [`Stencil::count`]: six neighbours (3D) of at most two whole counts each (a
/// Dirichlet one at its nearest, [`Cells::dirichlet_weight`]: `2 side / (side + 1)`).
const MAX_COUNT: usize = 2 * 6 * EIGHTHS as usize;

/// Red-black Gauss-Seidel sweeps before and after each coarse correction.
pub const SWEEPS: usize = 2;

/// The interpolation weight of the parent (`3/4`) and of its neighbour (`1/4`), per axis.
const NEAR: f64 = 0.75;
const FAR: f64 = 0.25;

/// Coordinates of cell `i` on a grid of `dims` (axis 0 fastest).
fn coords<const D: usize>(dims: &[usize; D], mut i: usize) -> [usize; D] {
    std::array::from_fn(|a| {
        let c = i % dims[a];
        i /= dims[a];
        c
    })
}

/// The cells `c` with `lo <= c < hi` (every axis), axis 0 fastest.
fn block_cells<const D: usize>(lo: [usize; D], hi: [usize; D]) -> impl Iterator<Item = [usize; D]> {
    let mut next = (0..D).all(|a| lo[a] < hi[a]).then_some(lo);
    std::iter::from_fn(move || {
        let c = next?;
        let mut n = c;
        next = (0..D).find_map(|a| {
            n[a] += 1;
            if n[a] < hi[a] {
                return Some(n);
            }
            n[a] = lo[a];
            None
        });
        Some(c)
    })
}

/// A level's grid: its dimensions and the linear index strides.
#[derive(Clone, Copy, Debug)]
struct Shape<const D: usize> {
    dims: [usize; D],
    stride: [usize; D],
}

impl<const D: usize> Shape<D> {
    fn new(dims: [usize; D]) -> Self {
        let stride = crate::grid::strides(&dims);
        Shape { dims, stride }
    }

    fn cells(&self) -> usize {
        self.dims.iter().product()
    }

    fn index(&self, c: [usize; D]) -> usize {
        (0..D).map(|a| c[a] * self.stride[a]).sum()
    }

    /// The halved grid of the next level (rounding up).
    fn coarser(&self) -> Self {
        Shape::new(self.dims.map(|d| d.div_ceil(2)))
    }
}

/// A value per face of a cell: `[a][0]` the `-a` one, `[a][1]` the `+a` one.
type Faces<const D: usize> = [[u8; 2]; D];

/// A row's cell coordinates, stored so that no loop of the V-cycle divides.
type At<const D: usize> = [u16; D];

fn widen<const D: usize>(c: At<D>) -> [usize; D] {
    c.map(usize::from)
}

/// The interpolation weight of corner `mask` of [`corners`]: `3/4` per axis not in the
/// mask, `1/4` per axis in it.
fn corner_weight<const D: usize>(mask: usize) -> f64 {
    (0..D).fold(1.0, |w, a| w * if mask >> a & 1 == 0 { NEAR } else { FAR })
}

/// The `2^D` coarse cells fine cell `f` interpolates from: corner `mask` is the parent
/// `f / 2` moved, along each axis in `mask`, one cell to `f`'s side. Returns the parent's
/// index and the index step of each axis's move.
fn corners<const D: usize>(f: [usize; D], coarse: &Shape<D>) -> (usize, [isize; D]) {
    let parent = f.map(|v| v / 2);
    let step = std::array::from_fn(|a| match f[a] % 2 {
        1 => coarse.stride[a] as isize,
        _ => -(coarse.stride[a] as isize),
    });
    (coarse.index(parent), step)
}

/// The axes along which the corners of fine cell `f` may move ([`corners`]): those whose
/// move stays inside the coarse grid and crosses an open face of `coarse`.
fn movable<const D: usize>(f: [usize; D], coarse: &Cells<D>) -> u8 {
    let (parent, step) = corners(f, &coarse.shape);
    let mut axes = 0;
    for a in 0..D {
        let mut lower = f.map(|v| v / 2);
        let i = match f[a] % 2 {
            1 if lower[a] + 1 < coarse.shape.dims[a] => parent,
            0 if lower[a] > 0 => parent.wrapping_add_signed(step[a]),
            _ => continue,
        };
        lower[a] -= 1 - f[a] % 2;
        if coarse.open(i, lower, a) {
            axes |= 1 << a;
        }
    }
    axes
}

/// The index of corner `mask` from [`corners`]' parent and steps.
fn corner(parent: usize, step: &[isize], mask: usize) -> usize {
    let moved: isize = (0..step.len())
        .filter(|a| mask >> a & 1 == 1)
        .map(|a| step[a])
        .sum();
    parent.wrapping_add_signed(moved)
}

/// One row of a level's matrix: its neighbours' rows and its diagonal over the level's
/// scale, in [`EIGHTHS`]: one whole count per neighbour that is not Neumann, but on the
/// coarse levels a Dirichlet neighbour's weight from its distance ([`Cells::dirichlet_weight`]).
/// A row whose cell, or whose `+axis` neighbour, is cut by the grid's upper boundary (a
/// coarse level's last cell along an axis whose finest cells do not fill it) says so in
/// `partial`, and its faces are weighted ([`Operator::face_weight`]); `count` then still
/// tells which neighbours it has, and [`Operator::partial_diag`] holds its diagonal.
#[derive(Clone, Copy, Debug)]
struct Stencil<const D: usize> {
    plus: [u32; D],
    minus: [u32; D],
    count: u8,
    /// Bit `a`: the cell is cut along axis `a`; bit `D + a`: its `+a` neighbour is.
    partial: u8,
}

/// One level's matrix: `unit * count` on the diagonal, `-scale` to each unknown neighbour.
struct Operator<const D: usize> {
    shape: Shape<D>,
    /// One more than the row of each cell, 0 for none (a fresh zeroed array costs memory only
    /// where the rows are).
    row: Vec<u32>,
    /// Cell of each row: the red rows (even coordinate sum) first, then the black ones.
    at: Vec<At<D>>,
    /// How many rows are red.
    red: usize,
    stencil: Vec<Stencil<D>>,
    /// The black rows with no coupling at all (zero diagonal), ascending: rare, and the only
    /// black rows whose `x` a half-sweep adds to rather than overwrites.
    lonely: Vec<u32>,
    scale: f64,
    /// The diagonal's unit: `scale / EIGHTHS`.
    unit: f64,
    /// `1 / D'` by [`Stencil::count`]: `1 / (unit * count)`, and `1 / scale` for none.
    inverse: [f64; MAX_COUNT + 1],
    /// Per axis, the share of the level's last cell that lies within the grid (1 where the
    /// finest cells fill it).
    extent: [f64; D],
    /// The diagonal over `scale` of each row with [`Stencil::partial`] bits (any value for
    /// the others); empty when the level has none.
    partial_diag: Vec<f64>,
    /// The Dirichlet cells next to the rows, and how prolongation extrapolates into them
    /// (empty on the finest level).
    ghosts: Ghosts<D>,
}

/// The Dirichlet cells of a coarse level next to its rows, each with the rows whose values it
/// takes in prolongation: ghost `g` at cell `cell[g]` is `sum alpha x[row]` over
/// `from[first[g]..first[g + 1]]`.
struct Ghosts<const D: usize> {
    cell: Vec<u32>,
    /// Each ghost's cell coordinates, so that restriction gathers there without dividing.
    at: Vec<At<D>>,
    first: Vec<u32>,
    from: Vec<(u32, f64)>,
}

impl<const D: usize> Default for Ghosts<D> {
    fn default() -> Self {
        Ghosts {
            cell: vec![],
            at: vec![],
            first: vec![],
            from: vec![],
        }
    }
}

impl<const D: usize> Ghosts<D> {
    /// The ghosts of the rows of `cells` (the `unknown` ones, each at row `level_row` with its
    /// faces' Dirichlet `weight`): a row's Dirichlet neighbour across a face
    /// extrapolates it linearly to the zero at distance `theta` ([`Cells::dirichlet_weight`]):
    /// `x (1 - 1 / theta)`, averaged over the rows it neighbours.
    fn new(cells: &Cells<D>, unknown: &[At<D>], level_row: &[u32], weight: &[Faces<D>]) -> Self {
        let mut pairs: Vec<(u32, u32, u8)> = (0..unknown.len())
            .into_par_iter()
            .with_min_len(ROW_GRAIN)
            .flat_map_iter(|k| {
                let mut v = Vec::new();
                cells.for_each_face(widen(unknown[k]), |a, plus, nb, class| {
                    if class == CellClass::Dirichlet {
                        v.push((nb as u32, level_row[k], weight[k][a][plus as usize]));
                    }
                });
                v
            })
            .collect();
        pairs.par_sort_unstable();
        let mut g = Ghosts::default();
        for group in pairs.chunk_by(|p, q| p.0 == q.0) {
            g.cell.push(group[0].0);
            g.at.push(coords(&cells.shape.dims, group[0].0 as usize).map(|v| v as u16));
            g.first.push(g.from.len() as u32);
            let m = group.len() as f64;
            for &(_, row, w) in group {
                g.from.push((row, (1.0 - w as f64 / EIGHTHS as f64) / m));
            }
        }
        g.first.push(g.from.len() as u32);
        g
    }

    fn len(&self) -> usize {
        self.cell.len()
    }

    fn sources(&self, g: usize) -> &[(u32, f64)] {
        &self.from[self.first[g] as usize..self.first[g + 1] as usize]
    }

    /// Writes each ghost's value from the rows' `x` at its cell of `dense` (`E x`).
    fn extrapolate(&self, x: &[f64], dense: &mut [f64]) {
        let values: Vec<f64> = (0..self.len())
            .into_par_iter()
            .with_min_len(ROW_GRAIN)
            .map(|g| {
                self.sources(g)
                    .iter()
                    .map(|&(r, a)| a * x[r as usize])
                    .sum()
            })
            .collect();
        for (&cell, v) in self.cell.iter().zip(values) {
            dense[cell as usize] = v;
        }
    }

    /// Adds each ghost's `sums` entry back to its rows' `b` (`E^T`), in the ghosts' order.
    fn hand_back(&self, sums: &[f64], b: &mut [f64]) {
        for (g, &sum) in sums.iter().enumerate() {
            for &(r, a) in self.sources(g) {
                b[r as usize] += a * sum;
            }
        }
    }
}

/// A level's rows in their order: its unknown cells `cells` (ascending), the red ones (even
/// coordinate sum) first, then the black ones, each colour ascending. Returns the index in
/// `cells` of each row, how many rows are red, and the row of each of `cells`.
fn red_black<const D: usize>(cells: &[At<D>]) -> (Vec<u32>, usize, Vec<u32>) {
    let is_red = |c: &At<D>| c.iter().map(|&v| v as usize).sum::<usize>() % 2 == 0;
    let red = cells
        .par_iter()
        .with_min_len(PAR_GRAIN)
        .filter(|c| is_red(c))
        .count();
    let (mut order, mut row) = (vec![0; cells.len()], Vec::with_capacity(cells.len()));
    let (mut next_red, mut next_black) = (0, red);
    for (k, c) in cells.iter().enumerate() {
        let next = if is_red(c) {
            &mut next_red
        } else {
            &mut next_black
        };
        order[*next] = k as u32;
        row.push(*next as u32);
        *next += 1;
    }
    (order, red, row)
}

impl<const D: usize> Operator<D> {
    /// The finest level: the system's own matrix ([`Finest::matrix`]). Returns it with the
    /// level's row of each system row.
    fn finest(finest: &Finest<D>) -> (Self, Vec<u32>) {
        let shape = Shape::new(finest.dims);
        let cells: Vec<At<D>> = (finest.unknowns.par_iter().with_min_len(PAR_GRAIN))
            .map(|&c| coords(&shape.dims, c).map(|v| v as u16))
            .collect();
        let a = finest.matrix;
        Self::build(shape, &cells, 1.0, |j, _, level_row| {
            let to_level = |r: u32| {
                if r == NONE {
                    NONE
                } else {
                    level_row[r as usize]
                }
            };
            Stencil {
                plus: a.plus[j].map(to_level),
                minus: a.minus[j].map(to_level),
                count: a.diag[j] as u8 * EIGHTHS,
                partial: 0,
            }
        })
    }

    /// A coarser level: the stencil of the module doc on `cells`, scaled by `scale`.
    fn new(cells: &Cells<D>, scale: f64) -> Self {
        let unknown = cells.unknowns();
        let weight: Vec<Faces<D>> = (unknown.par_iter().with_min_len(ROW_GRAIN))
            .map(|&c| cells.dirichlet_weights(widen(c)))
            .collect();
        let stencil = |k: usize, row: &[u32], _: &[u32]| {
            Self::stencil_of(cells, row, widen(unknown[k]), &weight[k])
        };
        let (mut op, level_row) = Self::build(cells.shape, &unknown, scale, stencil);
        op.extent = std::array::from_fn(|a| cells.extent(cells.shape.dims[a] - 1, a));
        if op.stencil.iter().any(|s| s.partial != 0) {
            let mut diag = vec![0.0; op.len()];
            for (k, &r) in level_row.iter().enumerate() {
                let s = &op.stencil[r as usize];
                if s.partial != 0 {
                    diag[r as usize] = op.weighted_diag(cells, widen(unknown[k]), s, &weight[k]);
                }
            }
            op.partial_diag = diag;
        }
        op.ghosts = Ghosts::new(cells, &unknown, &level_row, &weight);
        op
    }

    /// The level of `scale` whose rows are `cells` (ascending) in the order of [`red_black`],
    /// the stencil of each from `stencil(k, row, level_row)`: `k` its index in `cells`, `row`
    /// [`Operator::row`], `level_row` the row of each of `cells`. Returns it with `level_row`.
    fn build(
        shape: Shape<D>,
        cells: &[At<D>],
        scale: f64,
        stencil: impl Fn(usize, &[u32], &[u32]) -> Stencil<D> + Sync,
    ) -> (Self, Vec<u32>) {
        let (order, red, level_row) = red_black(cells);
        let at: Vec<At<D>> = order.par_iter().map(|&k| cells[k as usize]).collect();
        let mut row = vec![0u32; shape.cells()];
        for (r, &c) in at.iter().enumerate() {
            row[shape.index(widen(c))] = r as u32 + 1;
        }
        let stencil: Vec<Stencil<D>> = (order.par_iter().with_min_len(ROW_GRAIN))
            .map(|&k| stencil(k as usize, &row, &level_row))
            .collect();
        let lonely = (red..stencil.len())
            .filter(|&i| stencil[i].count == 0)
            .map(|i| i as u32)
            .collect();
        let unit = scale / EIGHTHS as f64;
        let op = Operator {
            shape,
            row,
            at,
            red,
            stencil,
            lonely,
            scale,
            unit,
            inverse: std::array::from_fn(|n| match n {
                0 => 1.0 / scale,
                n => 1.0 / (unit * n as f64),
            }),
            extent: [1.0; D],
            partial_diag: vec![],
            ghosts: Ghosts::default(),
        };
        (op, level_row)
    }

    /// The row of cell `c`: its neighbours across open faces.
    fn stencil_of(cells: &Cells<D>, row: &[u32], c: [usize; D], weight: &Faces<D>) -> Stencil<D> {
        let mut s = Stencil {
            plus: [NONE; D],
            minus: [NONE; D],
            count: 0,
            partial: 0,
        };
        for a in 0..D {
            let last = cells.shape.dims[a] - 1;
            s.partial |= ((cells.extent(c[a], a) < 1.0) as u8) << a;
            s.partial |= ((c[a] < last && cells.extent(c[a] + 1, a) < 1.0) as u8) << (D + a);
        }
        cells.for_each_face(c, |a, plus, nb, class| match class {
            CellClass::Neumann => {}
            CellClass::Unknown => {
                let r = row[nb] - 1;
                *(if plus {
                    &mut s.plus[a]
                } else {
                    &mut s.minus[a]
                }) = r;
                s.count += EIGHTHS;
            }
            CellClass::Dirichlet => s.count += weight[a][plus as usize],
        });
        s
    }

    /// The diagonal over `scale` of the row of cell `c` with stencil `s` and Dirichlet `weight`
    /// ([`Cells::dirichlet_weights`]), its faces weighted
    /// ([`Operator::face_weight`]; a Dirichlet neighbour's distance weight times the face's
    /// area): the sum of its off-diagonal weights where it has no Dirichlet neighbour, so that
    /// a closed region keeps the constants as its null space.
    fn weighted_diag(
        &self,
        cells: &Cells<D>,
        c: [usize; D],
        s: &Stencil<D>,
        weight: &Faces<D>,
    ) -> f64 {
        let mut diag = 0.0;
        cells.for_each_face(c, |a, plus, _, class| match class {
            CellClass::Neumann => {}
            CellClass::Unknown => diag += self.face_weight(s, a, plus),
            CellClass::Dirichlet => {
                let over_theta = weight[a][plus as usize] as f64 / EIGHTHS as f64;
                diag += self.face_area(s, a) * over_theta;
            }
        });
        diag
    }

    /// The area, in this level's faces, of the face along axis `a` of the cell with stencil
    /// `s`: the product of its extents within the grid across `a`.
    fn face_area(&self, s: &Stencil<D>, a: usize) -> f64 {
        (0..D)
            .filter(|&b| b != a && s.partial >> b & 1 == 1)
            .map(|b| self.extent[b])
            .product()
    }

    /// The weight of the coupling across the face along axis `a` (`plus`: the `+a` one) of
    /// the cell with stencil `s`: the face's area over the distance between the two cells'
    /// centroids, in this level's cells (a finite-volume flux; exactly 1 on a row without
    /// [`Stencil::partial`] bits, whose hot paths skip it). A cut
    /// cell is the last along its axis, so only a `+a` neighbour can be cut along `a`; the
    /// weight seen from either side is the same, and the operator stays symmetric.
    fn face_weight(&self, s: &Stencil<D>, a: usize, plus: bool) -> f64 {
        let extent = |bit: usize| match s.partial >> bit & 1 {
            1 => self.extent[a],
            _ => 1.0,
        };
        let other = if plus { extent(D + a) } else { 1.0 };
        self.face_area(s, a) * 2.0 / (extent(a) + other)
    }

    /// Row `i`'s diagonal.
    #[inline]
    fn diag(&self, i: usize) -> f64 {
        let s = &self.stencil[i];
        match s.partial {
            0 => self.unit * s.count as f64,
            _ => self.scale * self.partial_diag[i],
        }
    }

    fn len(&self) -> usize {
        self.at.len()
    }

    /// `scale` times the sum of `x` over row `i`'s unknown neighbours (each weighted by its
    /// face, [`Operator::face_weight`], on a row with [`Stencil::partial`] bits).
    #[inline]
    fn coupling(&self, i: usize, x: &[f64], offset: usize) -> f64 {
        let s = &self.stencil[i];
        if s.partial != 0 {
            return self.weighted_coupling(s, x, offset);
        }
        let mut sum = 0.0;
        for a in 0..D {
            for nb in [s.plus[a], s.minus[a]] {
                if nb != NONE {
                    sum += x[nb as usize - offset];
                }
            }
        }
        self.scale * sum
    }

    #[cold]
    fn weighted_coupling(&self, s: &Stencil<D>, x: &[f64], offset: usize) -> f64 {
        let mut sum = 0.0;
        for a in 0..D {
            for (nb, plus) in [(s.plus[a], true), (s.minus[a], false)] {
                if nb != NONE {
                    sum += self.face_weight(s, a, plus) * x[nb as usize - offset];
                }
            }
        }
        self.scale * sum
    }

    /// Gauss-Seidel on the rows of one colour, all at once (they read only the other
    /// colour): `x_i += (b - A x)_i / D'_i`, which is `x_i = (b_i + coupling) / diagonal` on
    /// a coupled row; on a row with a zero diagonal `D'_i` is the level's scale. With `fresh`,
    /// the colour's `x` is taken as zero, whatever it holds (the first sweep from `x = 0`,
    /// which need not clear it), and so is the black one's for the red rows: they are
    /// `b_i / D'_i`, with no neighbour read.
    fn half_sweep(&self, red: bool, fresh: bool, b: &[f64], x: &mut [f64]) {
        let (xr, xb) = x.split_at_mut(self.red);
        let (mine, other, first, other_first) = match red {
            true => (xr, &*xb, 0, self.red),
            false => (xb, &*xr, self.red, 0),
        };
        (mine.par_iter_mut().with_min_len(ROW_GRAIN))
            .enumerate()
            .for_each(|(k, xi)| {
                let i = first + k;
                let s = &self.stencil[i];
                let inverse = |n: u8| match s.partial {
                    0 => self.inverse[n as usize],
                    _ => 1.0 / self.diag(i),
                };
                match s.count {
                    0 if fresh => *xi = b[i] * self.inverse[0],
                    0 => *xi += b[i] * self.inverse[0],
                    n if fresh && red => *xi = b[i] * inverse(n),
                    n => {
                        let coupling = self.coupling(i, other, other_first);
                        *xi = (b[i] + coupling) * inverse(n)
                    }
                }
            });
    }

    /// `r = b - A x` on the rows `rows`.
    fn residual(&self, b: &[f64], x: &[f64], r: &mut [f64], rows: Range<usize>) {
        (r[rows.clone()].par_iter_mut().with_min_len(ROW_GRAIN))
            .enumerate()
            .for_each(|(k, ri)| {
                let i = rows.start + k;
                *ri = b[i] - self.diag(i) * x[i] + self.coupling(i, x, 0);
            });
    }

    /// `r = b - A x` right after a half-sweep of the black rows, which solved each coupled
    /// black row exactly: computed on the red rows only; on the black ones it is zero, and
    /// `b` on an uncoupled one ([`Operator::lonely`]: its diagonal and so its `A x` are zero).
    /// In exact arithmetic this is the full residual; it saves half of its pass.
    fn residual_after_black(&self, b: &[f64], x: &[f64], r: &mut [f64]) {
        self.residual(b, x, r, 0..self.red);
        (r[self.red..].par_iter_mut().with_min_len(PAR_GRAIN)).for_each(|ri| *ri = 0.0);
        for &i in &self.lonely {
            r[i as usize] = b[i as usize];
        }
    }

    /// `out = A x` ([`pcg::apply_dot`]: returns `x . out`).
    fn apply_dot(&self, x: &[f64], out: &mut [f64]) -> f64 {
        pcg::apply_dot(x, out, |i| self.diag(i) * x[i] - self.coupling(i, x, 0))
    }
}

/// A coarse cell's class from two of its children's (or of two groups of them): Dirichlet if
/// either is, else an unknown if either is, else Neumann.
fn coarser_class(a: CellClass, b: CellClass) -> CellClass {
    match (a, b) {
        (CellClass::Dirichlet, _) | (_, CellClass::Dirichlet) => CellClass::Dirichlet,
        (CellClass::Unknown, _) | (_, CellClass::Unknown) => CellClass::Unknown,
        _ => CellClass::Neumann,
    }
}

/// The bits of a kept cell's entry in [`Cells::code`]: its class (never 0, which marks a cell
/// not kept), then one bit per open face from [`OPEN_SHIFT`] on.
const CLASS_BITS: u8 = 3;
const OPEN_SHIFT: u32 = 2;

fn class_code(class: CellClass) -> u8 {
    match class {
        CellClass::Unknown => 1,
        CellClass::Dirichlet => 2,
        CellClass::Neumann => 3,
    }
}

fn class_of_code(code: u8) -> CellClass {
    match code & CLASS_BITS {
        1 => CellClass::Unknown,
        2 => CellClass::Dirichlet,
        _ => CellClass::Neumann,
    }
}

/// A level's cells as coarsening sees them: each one's class, and which of its faces are
/// open: the face to the next cell along axis `a` is open if at least one face of the finest
/// grid within it joins two cells that are not Neumann. Both are functions of the finest cells
/// a cell covers (its class: Dirichlet if any of them is, else an unknown if any is, else
/// Neumann), so any cell's can be worked out from them; a coarse level keeps, in
/// [`Cells::code`], those of the cells its levels ask about: within one cell of a parent of a
/// finer row ([`Cells::coarsen`]).
struct Cells<'a, const D: usize> {
    finest: &'a Finest<'a, D>,
    shape: Shape<D>,
    /// The side of a cell, in finest cells: `2^level`.
    side: usize,
    /// The kept cells, one ascending index range per line of cells along axis 0 (none on the
    /// finest level, which asks [`Finest::class`]).
    kept: Vec<Range<usize>>,
    /// Per cell, the class's code and the open faces' bits of a kept cell, 0 for any other
    /// (a fresh zeroed array: it costs memory only where cells are kept).
    code: Vec<u8>,
}

impl<'a, const D: usize> Cells<'a, D> {
    fn finest(finest: &'a Finest<'a, D>) -> Self {
        Cells {
            finest,
            shape: Shape::new(finest.dims),
            side: 1,
            kept: vec![],
            code: vec![],
        }
    }

    /// The class of cell `i`.
    #[inline]
    fn class(&self, i: usize) -> CellClass {
        if self.side == 1 {
            return (self.finest.class)(i);
        }
        match self.code[i] {
            0 => self.far_class(coords(&self.shape.dims, i)),
            code => class_of_code(code),
        }
    }

    /// Whether the face of cell `i` (coordinates `c`) to the next cell along axis `a` is open.
    #[inline]
    fn open(&self, i: usize, c: [usize; D], a: usize) -> bool {
        if c[a] + 1 >= self.shape.dims[a] {
            return false;
        }
        if self.side == 1 {
            return self.wet(i) && self.wet(i + self.shape.stride[a]);
        }
        match self.code[i] {
            0 => self.far_open(c, a),
            code => code >> (OPEN_SHIFT as usize + a) & 1 == 1,
        }
    }

    /// The share of the cells at coordinate `k` along axis `a` that lies within the grid: 1
    /// but for the last cell of a coarse level whose finest cells do not fill it.
    fn extent(&self, k: usize, a: usize) -> f64 {
        let n = self.finest.dims[a];
        (n.min((k + 1) * self.side) - k * self.side) as f64 / self.side as f64
    }

    /// Calls `f(a, plus, nb, class)` for each open face of cell `c` (along axis `a`, `plus`
    /// the `+a` one) with the neighbour `nb` across it and its class.
    fn for_each_face(&self, c: [usize; D], mut f: impl FnMut(usize, bool, usize, CellClass)) {
        let shape = &self.shape;
        let i = shape.index(c);
        for a in 0..D {
            let mut lower = c;
            lower[a] = lower[a].wrapping_sub(1);
            let below = (c[a] > 0)
                .then(|| i - shape.stride[a])
                .filter(|&b| self.open(b, lower, a));
            let above = self.open(i, c, a).then(|| i + shape.stride[a]);
            for (nb, plus) in [(below, false), (above, true)] {
                if let Some(nb) = nb {
                    f(a, plus, nb, self.class(nb));
                }
            }
        }
    }

    /// The finest cells that cell `c` covers, as the corners of a block.
    fn block(&self, c: [usize; D]) -> ([usize; D], [usize; D]) {
        let n = &self.finest.dims;
        let lo = c.map(|v| v * self.side);
        (lo, std::array::from_fn(|a| (lo[a] + self.side).min(n[a])))
    }

    /// The diagonal term, in [`EIGHTHS`], that the Dirichlet neighbour of cell `c` across its
    /// face along axis `a` (`up`: the `+a` side) adds to `c`'s row: `1 / theta`, `theta` the
    /// distance from `c`'s centre to the first Dirichlet finest cell behind that face, in this
    /// level's cells, averaged over the finest columns across the face that reach one (Gibou et
    /// al. 2002's ghost fluid, as the finest level's zero would place it). With Dirichlet-first
    /// coarsening the neighbour is Dirichlet as soon as one finest cell of it is, so the coarse
    /// zero sits half a coarse cell nearer than the fine one on average; weighting it by its
    /// distance cut the PCG iterations of the half-full tank at 128^3 from 12 to 9 and of
    /// drop-3d at 200^3 from 11 to 9 (docs/benchmarks/pressure.md).
    fn dirichlet_weight(&self, c: [usize; D], a: usize, up: bool) -> u8 {
        let (side, fine) = (self.side, Shape::new(self.finest.dims));
        // The centroid of the cell's part within the grid, in half finest cells.
        let centre = 2 * c[a] * side + (fine.dims[a] - c[a] * side).min(side);
        // The finest layers behind the face, nearest first.
        let (near, depth) = match up {
            true => (
                (c[a] + 1) * side,
                side.min(fine.dims[a] - (c[a] + 1) * side),
            ),
            false => (c[a] * side - 1, side),
        };
        let layer = |k: usize| if up { near + k } else { near - k };
        let (mut lo, mut hi) = self.block(c);
        (lo[a], hi[a]) = (0, 1);
        let (mut sum, mut columns) = (0.0, 0);
        for mut f in block_cells(lo, hi) {
            let mut class_at = |p: usize| {
                f[a] = p;
                (self.finest.class)(fine.index(f))
            };
            let first = (0..depth)
                .map(|k| (layer(k), class_at(layer(k))))
                .find(|&(_, class)| class != CellClass::Unknown);
            if let Some((p, CellClass::Dirichlet)) = first {
                sum += 2.0 * side as f64 / (2 * p + 1).abs_diff(centre) as f64;
                columns += 1;
            }
        }
        match columns {
            0 => EIGHTHS,
            _ => (EIGHTHS as f64 * sum / columns as f64).round() as u8,
        }
    }

    /// [`Cells::dirichlet_weight`] of each face of cell `c` with a Dirichlet neighbour (0 for
    /// the others), worked out once for its stencil and its [`Ghosts`].
    fn dirichlet_weights(&self, c: [usize; D]) -> Faces<D> {
        let mut w = [[0; 2]; D];
        self.for_each_face(c, |a, plus, _, class| {
            if class == CellClass::Dirichlet {
                w[a][plus as usize] = self.dirichlet_weight(c, a, plus);
            }
        });
        w
    }

    /// [`Cells::class`] of a cell not kept, from the finest cells it covers (it stops at the
    /// first Dirichlet one: most such cells are air).
    #[cold]
    fn far_class(&self, c: [usize; D]) -> CellClass {
        let (lo, hi) = self.block(c);
        let fine = Shape::new(self.finest.dims);
        let mut class = CellClass::Neumann;
        for f in block_cells(lo, hi) {
            class = coarser_class(class, (self.finest.class)(fine.index(f)));
            if class == CellClass::Dirichlet {
                break;
            }
        }
        class
    }

    /// [`Cells::open`] of a cell not kept, below the grid's upper boundary along `a`: whether
    /// any pair of finest cells across its face are both not Neumann.
    #[cold]
    fn far_open(&self, c: [usize; D], a: usize) -> bool {
        let fine = Shape::new(self.finest.dims);
        let (mut lo, mut hi) = self.block(c);
        lo[a] = (c[a] + 1) * self.side - 1;
        hi[a] = lo[a] + 1;
        debug_assert!(hi[a] < fine.dims[a], "the next cell is inside the grid");
        block_cells(lo, hi).any(|f| {
            let i = fine.index(f);
            self.wet(i) && self.wet(i + fine.stride[a])
        })
    }

    /// Whether finest cell `f` is not Neumann.
    fn wet(&self, f: usize) -> bool {
        (self.finest.class)(f) != CellClass::Neumann
    }

    /// The unknown cells of a coarser level, ascending.
    fn unknowns(&self) -> Vec<At<D>> {
        let at = |c: usize| coords(&self.shape.dims, c).map(|v| v as u16);
        let unknown = |&c: &usize| class_of_code(self.code[c]) == CellClass::Unknown;
        (self.kept.par_iter())
            .flat_map_iter(|r| r.clone().filter(unknown).map(at))
            .collect()
    }

    /// The next coarser level's cells, keeping those within one cell (along every axis at
    /// once) of a parent of one of `rows` (this level's): the rows of the coarser level, their
    /// neighbours and the corners the rows interpolate from ([`corners`]). A coarse cell is
    /// unknown if any of its children is, else Dirichlet if any is, else Neumann; a coarse face
    /// is open if any fine face in it is.
    fn coarsen(&self, rows: &[At<D>]) -> Cells<'a, D> {
        let fine = &self.shape;
        let coarse = fine.coarser();
        let parents = rows.par_iter().map(|&f| widen(f).map(|v| v / 2));
        let spans = dilate(&coarse.dims, line_spans(&coarse.dims, parents), 1);
        let n0 = coarse.dims[0];
        let kept: Vec<Range<usize>> = (spans.iter().enumerate())
            .filter(|(_, s)| s[0] < s[1])
            .map(|(l, s)| l * n0 + s[0] as usize..l * n0 + s[1] as usize)
            .collect();
        let mut code = vec![0u8; coarse.cells()];
        par_runs(&kept, &mut code).for_each(|(r, run)| {
            let mut kc = coords(&coarse.dims, r.start);
            for (x, out) in (kc[0]..).zip(run) {
                kc[0] = x;
                *out = self.code_of_parent(kc);
            }
        });
        Cells {
            finest: self.finest,
            shape: coarse,
            side: 2 * self.side,
            kept,
            code,
        }
    }

    /// The [`Cells::code`] entry of coarse cell `kc` from its children on this level.
    fn code_of_parent(&self, kc: [usize; D]) -> u8 {
        let fine = &self.shape;
        let (mut class, mut open) = (CellClass::Neumann, 0);
        for mask in 0..1usize << D {
            let fc: [usize; D] = std::array::from_fn(|a| 2 * kc[a] + (mask >> a & 1));
            if (0..D).any(|a| fc[a] >= fine.dims[a]) {
                continue;
            }
            let f = fine.index(fc);
            class = coarser_class(class, self.class(f));
            // The child on the upper side of each axis carries that face.
            for a in (0..D).filter(|&a| mask >> a & 1 == 1) {
                open |= (self.open(f, fc, a) as u8) << a;
            }
        }
        class_code(class) | open << OPEN_SHIFT
    }
}

/// The `4^D` fine cells that may interpolate from a coarse cell `k` ([`corners`] seen from
/// the coarse side), per axis `2k - 1 + t` for `t` in `0..4`: each one's index offset from
/// `2k`, weight (`1/4` for `t` = 0 or 3, `3/4` for the children `t` = 1, 2), and the axes
/// along which its corner `k` moves from its parent (those with `t` = 0 or 3; none: a
/// child).
fn block<const D: usize>(fine: &Shape<D>) -> Vec<(isize, f64, u8)> {
    (0..1usize << (2 * D))
        .map(|code| {
            let t = |a: usize| (code >> (2 * a) & 3) as isize;
            let offset = (0..D).map(|a| (t(a) - 1) * fine.stride[a] as isize).sum();
            let moved = (0..D).filter(|&a| t(a) % 3 == 0).fold(0, |m, a| m | 1 << a);
            (offset, corner_weight::<D>(moved as usize), moved)
        })
        .collect()
}

/// The full-weighting sum `sum_j w_j dense[base + offset_j]` over the [`block`] of `4^D` fine
/// cells around the children of a coarse cell, `base` the index of its lowest child, with
/// every cell inside the grid: separably, since the weight of a cell is the product of one
/// `1/4` or `3/4` per axis. First the `4^{D-1}` lines along axis 0, then groups of four sums
/// along each further axis, each as `1/4 (a + d) + 3/4 (b + c)`: independent short sums that
/// the processor overlaps, where one running sum over the `4^D` cells waited on each
/// addition. With the zero residuals skipped row by row, restriction fell from a third of the
/// finest level's V-cycle time at drop-3d 300^3 to a fifth (docs/benchmarks/pressure.md).
fn full_weighting<const D: usize>(dense: &[f64], base: usize, stride: &[usize; D]) -> f64 {
    let weighted = |v: [f64; 4]| FAR * (v[0] + v[3]) + NEAR * (v[1] + v[2]);
    let mut sums = [0.0; 16];
    let lines = 1 << (2 * (D - 1));
    for (l, sum) in sums[..lines].iter_mut().enumerate() {
        let start = (1..D).fold(base - 1, |at, a| {
            let t = (l >> (2 * (a - 1)) & 3) as isize - 1;
            at.wrapping_add_signed(t * stride[a] as isize)
        });
        *sum = weighted(std::array::from_fn(|t| dense[start + t]));
    }
    let mut n = lines;
    while n > 1 {
        n /= 4;
        for g in 0..n {
            sums[g] = weighted(std::array::from_fn(|t| sums[4 * g + t]));
        }
    }
    sums[0]
}

/// `dense[cell of row i] = v[i]` for every row of `op`, in parallel over chunks of the grid:
/// each chunk writes the red rows and the black rows (each in ascending cell order) that
/// fall in it.
fn spread_rows<const D: usize>(dense: &mut [f64], op: &Operator<D>, v: &[f64]) {
    let cell = |i: usize| op.shape.index(widen(op.at[i]));
    dense
        .par_chunks_mut(PAR_GRAIN)
        .enumerate()
        .for_each(|(k, d)| {
            let (lo, hi) = (k * PAR_GRAIN, k * PAR_GRAIN + d.len());
            for (first, end) in [(0, op.red), (op.red, op.len())] {
                let start =
                    first + op.at[first..end].partition_point(|&c| op.shape.index(widen(c)) < lo);
                for i in start..end {
                    let c = cell(i);
                    if c >= hi {
                        break;
                    }
                    d[c - lo] = v[i];
                }
            }
        });
}

/// A level: its matrix, its vectors, and (below the coarsest) how it exchanges with the next.
struct Level<const D: usize> {
    op: Operator<D>,
    /// Per row, the axes its interpolation corners may move along ([`movable`]). Empty on
    /// the coarsest level, as is `to_parent`.
    movable: Vec<u8>,
    /// Per row, the interpolation weight of the corners that are Neumann or cannot be
    /// reached, which `P` gives the parent (exact in `f32`: sums of products of 1/4 and 3/4).
    to_parent: Vec<f32>,
    /// Per cell of the next coarser grid, whether a row among the `4^D` fine cells that may
    /// interpolate from it ([`block`]) does not move freely along all axes or gives its parent
    /// something extra; where none does, restriction is the plain full-weighting sum (empty on
    /// the coarsest level; a fresh zeroed array, touched only around the loose rows).
    loose: Vec<bool>,
    /// The level's solution and right-hand side in the V-cycle; empty on the finest level,
    /// which works on CG's vectors ([`v_cycle`]).
    x: Vec<f64>,
    b: Vec<f64>,
    r: Vec<f64>,
    /// One value per cell of the level's grid, zero outside the rows: a row vector spread
    /// over the grid ([`Level::spread`]), so that the transfers read a neighbour's value at
    /// its cell without looking its row up. It holds `r` while restricting to the next level
    /// and `x` while prolonging to the previous one.
    dense: Vec<f64>,
}

impl<const D: usize> Level<D> {
    /// The level of `op`, with its own `x` and `b` unless it is the `finest`.
    fn new(op: Operator<D>, finest: bool) -> Self {
        let (n, own) = (op.len(), if finest { 0 } else { op.len() });
        Level {
            op,
            movable: vec![],
            to_parent: vec![],
            loose: vec![],
            x: vec![0.0; own],
            b: vec![0.0; own],
            r: vec![0.0; n],
            dense: vec![],
        }
    }

    /// Writes `r` (`residual`) or else `x` at the rows' cells of [`Level::dense`]; the other
    /// cells stay zero.
    fn spread(&mut self, residual: bool) {
        let cells = self.op.shape.cells();
        if self.dense.len() != cells {
            self.dense = vec![0.0; cells];
        }
        let v = if residual { &self.r } else { &self.x };
        spread_rows(&mut self.dense, &self.op, v);
    }

    /// Sets [`Level::movable`], [`Level::to_parent`] and [`Level::loose`] from the next
    /// level's cells.
    fn link(&mut self, coarse: &Cells<D>) {
        let at = self.op.at.par_iter().with_min_len(ROW_GRAIN);
        self.movable = at.map(|&f| movable(widen(f), coarse)).collect();
        let at = self.op.at.par_iter().with_min_len(ROW_GRAIN);
        self.to_parent = (at.zip(&self.movable))
            .map(|(&f, &axes)| {
                let (parent, step) = corners(widen(f), &coarse.shape);
                let neumann = |m: usize| {
                    m & !axes as usize != 0
                        || coarse.class(corner(parent, &step, m)) == CellClass::Neumann
                };
                let w: f64 = (0..1 << D)
                    .filter(|&m| neumann(m))
                    .map(corner_weight::<D>)
                    .sum();
                w as f32
            })
            .collect();
        // A row that is not free marks the coarse cells whose block holds it: its corners.
        let full = (1u8 << D) - 1;
        let loose: Vec<usize> = (0..self.op.len())
            .into_par_iter()
            .with_min_len(PAR_GRAIN)
            .filter(|&i| self.movable[i] != full || self.to_parent[i] != 0.0)
            .collect();
        let shape = &coarse.shape;
        self.loose = vec![false; shape.cells()];
        for i in loose {
            let f = widen(self.op.at[i]);
            for m in 0..1usize << D {
                let k: [Option<usize>; D] = std::array::from_fn(|a| match (m >> a & 1, f[a] % 2) {
                    (0, _) => Some(f[a] / 2),
                    (_, 1) => Some(f[a] / 2 + 1).filter(|&k| k < shape.dims[a]),
                    _ => (f[a] / 2).checked_sub(1),
                });
                if k.iter().all(Option::is_some) {
                    self.loose[shape.index(k.map(Option::unwrap))] = true;
                }
            }
        }
    }

    /// Pre-smoothing from `x = 0`: `SWEEPS` times red then black, the first sweep
    /// [`Operator::half_sweep`]'s `fresh` one (so `x` need not be cleared first).
    fn pre_smooth(&self, b: &[f64], x: &mut [f64]) {
        for sweep in 0..SWEEPS {
            self.op.half_sweep(true, sweep == 0, b, x);
            self.op.half_sweep(false, sweep == 0, b, x);
        }
    }

    /// Post-smoothing, the transpose of [`Level::pre_smooth`]: black then red.
    fn post_smooth(&self, b: &[f64], x: &mut [f64]) {
        for _ in 0..SWEEPS {
            self.op.half_sweep(false, false, b, x);
            self.op.half_sweep(true, false, b, x);
        }
    }

    /// `coarse.b = P^T r` (restriction of this level's residual), a gather over [`block`]:
    /// from [`Level::dense`] alone where the block is not [`Level::loose`], else row by row;
    /// gathered at the coarse level's [`Ghosts`] too and handed back to their rows.
    fn restrict(&mut self, coarse: &mut Level<D>) {
        self.spread(true);
        let (cop, block) = (&coarse.op, block(&self.op.shape));
        (coarse.b.par_iter_mut().with_min_len(ROW_GRAIN / 4))
            .zip(&cop.at)
            .for_each(|(b, &k)| *b = self.gather(&block, cop, widen(k)));
        // The Dirichlet cells prolongation extrapolates into: `R = E^T P^T`.
        let ghosts = &cop.ghosts;
        let sums: Vec<f64> = (ghosts.at.par_iter().with_min_len(ROW_GRAIN / 4))
            .map(|&k| self.gather(&block, cop, widen(k)))
            .collect();
        ghosts.hand_back(&sums, &mut coarse.b);
    }

    /// `(P^T r)` at cell `k` of the coarse level `cop`, from this level's residual as
    /// [`Level::restrict`] spread it: the full-weighting sum over the [`block`] where it is
    /// interior and not [`Level::loose`], else row by row with each row's corners.
    fn gather(&self, block: &[(isize, f64, u8)], cop: &Operator<D>, k: [usize; D]) -> f64 {
        let (fine, dense) = (&self.op.shape, &self.dense);
        let base = fine.index(k.map(|v| 2 * v));
        let interior = (0..D).all(|a| k[a] > 0 && 2 * k[a] + 2 < fine.dims[a]);
        if interior && !self.loose[cop.shape.index(k)] {
            return full_weighting(dense, base, &fine.stride);
        }
        let inside = |code: usize| {
            (0..D).all(|a| (2 * k[a] + (code >> (2 * a) & 3)).wrapping_sub(1) < fine.dims[a])
        };
        let mut sum = 0.0;
        for (code, &(offset, w, moved)) in block.iter().enumerate() {
            if !interior && !inside(code) {
                continue;
            }
            // A zero residual (a black row's, or no row's) adds nothing.
            if dense[base.wrapping_add_signed(offset)] == 0.0 {
                continue;
            }
            let r = self.op.row[base.wrapping_add_signed(offset)] as usize;
            let Some(r) = r.checked_sub(1) else { continue };
            if moved & !self.movable[r] != 0 {
                continue;
            }
            let w = if moved == 0 {
                w + self.to_parent[r] as f64
            } else {
                w
            };
            sum += w * self.r[r];
        }
        sum
    }

    /// `x += P coarse.x` (prolongation of the coarse correction), reading the corners'
    /// values from the coarse level's [`Level::dense`] (its [`Ghosts`] written there first;
    /// zero at the other Dirichlet cells and at Neumann cells). Only on the red rows and
    /// [`Operator::lonely`]: post-smoothing starts with the black rows, and overwrites every
    /// other black row's `x` without reading it.
    fn prolong_add(&self, coarse: &mut Level<D>, x: &mut [f64]) {
        coarse.spread(false);
        (coarse.op.ghosts).extrapolate(&coarse.x, &mut coarse.dense);
        let (cop, xc) = (&coarse.op, &coarse.dense);
        let (op, to_parent, movable) = (&self.op, &self.to_parent, &self.movable);
        let weight: Vec<f64> = (0..1 << D).map(corner_weight::<D>).collect();
        let correction = |i: usize| {
            let (parent, step) = corners(widen(op.at[i]), &cop.shape);
            let inside = movable[i] as usize;
            let mut sum = to_parent[i] as f64 * xc[parent];
            let mut cell = [parent; 8];
            for m in 1usize..1 << D {
                let low = m.trailing_zeros() as usize;
                cell[m] = cell[m & (m - 1)].wrapping_add_signed(step[low]);
            }
            for m in 0..1 << D {
                if m & !inside == 0 {
                    sum += weight[m] * xc[cell[m]];
                }
            }
            sum
        };
        (x[..op.red].par_iter_mut().with_min_len(ROW_GRAIN))
            .enumerate()
            .for_each(|(i, x)| *x += correction(i));
        for &i in &op.lonely {
            x[i as usize] += correction(i as usize);
        }
        // Restriction reads this grid's other cells as zero.
        for &cell in &cop.ghosts.cell {
            coarse.dense[cell as usize] = 0.0;
        }
    }
}

/// The coarsest level's exact solve: a dense Cholesky factor of its matrix, with
/// `(scale / |K|) 1_K 1_K^T` added on every closed part `K` (see the module doc).
struct Dense {
    n: usize,
    /// The factor `L` in the lower triangle and `L^T` in the upper one, row-major, so that
    /// both substitutions read rows.
    l: Vec<f64>,
}

impl Dense {
    fn new<const D: usize>(op: &Operator<D>) -> Self {
        let n = op.len();
        let mut a = vec![0.0; n * n];
        for (i, s) in op.stencil.iter().enumerate() {
            a[i * n + i] = op.diag(i);
            for ax in 0..D {
                for (j, plus) in [(s.plus[ax], true), (s.minus[ax], false)] {
                    if j != NONE {
                        a[i * n + j as usize] = -op.scale * op.face_weight(s, ax, plus);
                    }
                }
            }
        }
        for part in closed_parts(op) {
            let c = op.scale / part.len() as f64;
            for &i in &part {
                for &j in &part {
                    a[i * n + j] += c;
                }
            }
        }
        cholesky(n, &mut a);
        for i in 0..n {
            for j in 0..i {
                a[j * n + i] = a[i * n + j];
            }
        }
        Dense { n, l: a }
    }

    /// `x = (L L^T)^-1 b`.
    fn solve(&self, b: &[f64], x: &mut [f64]) {
        let (n, l) = (self.n, &self.l);
        for i in 0..n {
            x[i] = (b[i] - dot4(&l[i * n..i * n + i], &x[..i])) / l[i * n + i];
        }
        for i in (0..n).rev() {
            x[i] = (x[i] - dot4(&l[i * n + i + 1..(i + 1) * n], &x[i + 1..])) / l[i * n + i];
        }
    }
}

/// `a . b` in four interleaved partial sums, so that the processor overlaps the additions
/// (one running sum waits on each): the dense factor's and its solves' inner loop.
fn dot4(a: &[f64], b: &[f64]) -> f64 {
    let mut s = [0.0; 4];
    let (a4, b4) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = (a4.remainder().iter().zip(b4.remainder()))
        .map(|(p, q)| p * q)
        .sum();
    for (p, q) in a4.zip(b4) {
        for k in 0..4 {
            s[k] += p[k] * q[k];
        }
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// In-place Cholesky `A = L L^T` of a symmetric positive definite row-major `n x n` matrix;
/// the lower triangle receives `L` (the upper is left as it was and never read).
fn cholesky(n: usize, a: &mut [f64]) {
    for j in 0..n {
        let d = a[j * n + j] - dot4(&a[j * n..j * n + j], &a[j * n..j * n + j]);
        assert!(d > 0.0, "coarsest multigrid matrix not positive definite");
        let d = d.sqrt();
        a[j * n + j] = d;
        let (above, below) = a.split_at_mut((j + 1) * n);
        let row_j = &above[j * n..j * n + j];
        for row_i in below.chunks_exact_mut(n) {
            row_i[j] = (row_i[j] - dot4(&row_i[..j], row_j)) / d;
        }
    }
}

/// The connected parts of a level's rows that touch no Dirichlet cell, each as its rows.
fn closed_parts<const D: usize>(op: &Operator<D>) -> Vec<Vec<usize>> {
    let mut seen = vec![false; op.len()];
    let mut parts = vec![];
    for start in 0..op.len() {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let (mut part, mut stack, mut open) = (vec![], vec![start], false);
        while let Some(i) = stack.pop() {
            part.push(i);
            let s = &op.stencil[i];
            let unknown = s.plus.iter().chain(&s.minus).filter(|&&j| j != NONE);
            open |= EIGHTHS as usize * unknown.clone().count() < s.count as usize;
            for &j in unknown {
                if !std::mem::replace(&mut seen[j as usize], true) {
                    stack.push(j as usize);
                }
            }
        }
        if !open {
            parts.push(part);
        }
    }
    parts
}

/// The V-cycle of `levels[0]` on `b`, into `x` (each coarser level on its own vectors).
fn v_cycle<const D: usize>(levels: &mut [Level<D>], coarsest: &Dense, b: &[f64], x: &mut [f64]) {
    let (fine, rest) = levels.split_first_mut().expect("at least one level");
    let Some(coarse) = rest.first_mut() else {
        coarsest.solve(b, x);
        return;
    };
    fine.pre_smooth(b, x);
    fine.op.residual_after_black(b, x, &mut fine.r);
    fine.restrict(coarse);
    let (coarse_b, mut coarse_x) = (std::mem::take(&mut coarse.b), std::mem::take(&mut coarse.x));
    v_cycle(rest, coarsest, &coarse_b, &mut coarse_x);
    let coarse = &mut rest[0];
    (coarse.b, coarse.x) = (coarse_b, coarse_x);
    fine.prolong_add(coarse, x);
    fine.post_smooth(b, x);
}

/// The multigrid preconditioner of one system: the level hierarchy, built once per solve.
/// CG runs in the finest level's row order, with its operator as the matrix
/// ([`Preconditioned`]), so that a V-cycle reads CG's residual and writes its `z` in place.
pub struct Multigrid<const D: usize> {
    levels: Vec<Level<D>>,
    coarsest: Dense,
    /// The finest level's row of each system row (unknown cells in ascending order).
    level_row: Vec<u32>,
}

impl<const D: usize> Multigrid<D> {
    /// The hierarchy of the system of `finest` (see the module doc).
    pub fn new(finest: &Finest<D>) -> Self {
        assert!(
            finest.dims.iter().all(|&d| d <= 1 << 16),
            "at most 2^16 cells per axis"
        );
        let mut cells = Cells::finest(finest);
        let (op, level_row) = Operator::finest(finest);
        let finest_rows = op.len();
        let mut levels = vec![Level::new(op, true)];
        let coarser = 2f64.powi(D as i32 - 2);
        loop {
            let fine = levels.last_mut().expect("the finest level");
            if fine.op.len() <= COARSEST_ROWS {
                break;
            }
            let next_cells = cells.coarsen(&fine.op.at);
            let next = Operator::new(&next_cells, fine.op.scale * coarser);
            if loses_the_liquid::<D>(fine.op.len(), next.len(), finest_rows) {
                break;
            }
            fine.link(&next_cells);
            cells = next_cells;
            levels.push(Level::new(next, false));
        }
        let coarsest = Dense::new(&levels.last().expect("the coarsest level").op);
        Multigrid {
            levels,
            coarsest,
            level_row,
        }
    }
}

impl<const D: usize> Preconditioned for Multigrid<D> {
    /// The finest level's operator: the system's matrix, in that level's row order.
    fn apply_dot(&self, x: &[f64], out: &mut [f64]) -> f64 {
        self.levels[0].op.apply_dot(x, out)
    }

    /// `z = B r`, `B` one V-cycle from zero.
    fn precondition(&mut self, r: &[f64], z: &mut [f64]) {
        v_cycle(&mut self.levels, &self.coarsest, r, z);
    }
}

/// Solves the system of `finest` (`b` and `x` in its row order) by CG preconditioned with
/// the V-cycle (MGPCG, McAdams sec. 3), from the guess `x` holds (zeros for a cold start); the
/// hierarchy is built only if CG has to iterate ([`pcg::settled`]: a warm start may already be
/// within the tolerance). CG runs in the finest level's row order: `b`, `x` and the start's
/// residual are taken into it and `x` out of it once per solve, not once per iteration.
pub fn solve<const D: usize>(
    finest: &Finest<D>,
    b: &[f64],
    x: &mut [f64],
    settings: &PcgSettings,
) -> PcgStats {
    let r = pcg::start_residual(b, x, |i| finest.matrix.row(i, x));
    if let Some(stats) = pcg::settled(b, &r, settings) {
        return stats;
    }
    let mut mg = Multigrid::new(finest);
    let to_level = |v: &[f64]| {
        let mut level = vec![0.0; v.len()];
        for (&j, &v) in mg.level_row.iter().zip(v) {
            level[j as usize] = v;
        }
        level
    };
    let (level_b, mut level_x) = (to_level(b), to_level(x));
    let level_r = match r {
        Cow::Borrowed(_) => level_b.clone(),
        Cow::Owned(r) => to_level(&r),
    };
    let stats = pcg::solve_with(&mut mg, &level_b, &mut level_x, level_r, settings);
    (x.par_iter_mut().with_min_len(PAR_GRAIN))
        .zip(&mg.level_row)
        .for_each(|(x, &j)| *x = level_x[j as usize]);
    stats
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solvers::pcg::{self, PcgSettings, PcgStats, StencilMatrix};
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// The system of the module doc, built directly (as `Poisson` builds it, and
    /// independently of [`Operator`]).
    fn system<const D: usize>(dims: [usize; D], class: &[CellClass]) -> StencilMatrix<D> {
        let shape = Shape::new(dims);
        let mut row = vec![NONE; class.len()];
        let unknown = (0..class.len()).filter(|&c| class[c] == CellClass::Unknown);
        for (r, c) in unknown.clone().enumerate() {
            row[c] = r as u32;
        }
        let mut a = StencilMatrix::<D>::default();
        for c in unknown {
            let cc = coords(&dims, c);
            let (mut diag, mut plus, mut minus) = (0.0, [NONE; D], [NONE; D]);
            for k in 0..D {
                if cc[k] > 0 && class[c - shape.stride[k]] != CellClass::Neumann {
                    diag += 1.0;
                    minus[k] = row[c - shape.stride[k]];
                }
                if cc[k] + 1 < dims[k] && class[c + shape.stride[k]] != CellClass::Neumann {
                    diag += 1.0;
                    plus[k] = row[c + shape.stride[k]];
                }
            }
            a.diag.push(diag);
            a.plus.push(plus);
            a.minus.push(minus);
            a.off_plus
                .push(plus.map(|p| if p == NONE { 0.0 } else { -1.0 }));
        }
        a
    }

    /// The multigrid of the system of `class` (one per cell of `dims`).
    fn multigrid<const D: usize>(dims: [usize; D], class: &[CellClass]) -> Multigrid<D> {
        let unknowns: Vec<usize> = (0..class.len())
            .filter(|&c| class[c] == CellClass::Unknown)
            .collect();
        Multigrid::new(&Finest {
            dims,
            class: &|c| class[c],
            unknowns: &unknowns,
            matrix: &system(dims, class),
        })
    }

    /// Each cell solid with probability `solid`, else empty with probability `air`, else
    /// fluid.
    fn random_classes(cells: usize, solid: f64, air: f64, rng: &mut StdRng) -> Vec<CellClass> {
        (0..cells)
            .map(|_| match rng.random::<f64>() {
                u if u < solid => CellClass::Neumann,
                u if u < solid + air => CellClass::Dirichlet,
                _ => CellClass::Unknown,
            })
            .collect()
    }

    fn random_vector(n: usize, rng: &mut StdRng) -> Vec<f64> {
        (0..n).map(|_| rng.random::<f64>() - 0.5).collect()
    }

    fn dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(p, q)| p * q).sum()
    }

    fn max_abs(a: &[f64]) -> f64 {
        a.iter().fold(0.0, |m, v| m.max(v.abs()))
    }

    /// MGPCG on the system of `class` to `tolerance`; checks the reported and the true
    /// residual against it and returns `(x, A, stats)`.
    fn solve<const D: usize>(
        dims: [usize; D],
        class: &[CellClass],
        b: &[f64],
        tolerance: f64,
    ) -> (Vec<f64>, StencilMatrix<D>, PcgStats) {
        let a = system(dims, class);
        let mut x = vec![0.0; a.len()];
        let settings = PcgSettings {
            tolerance,
            ..Default::default()
        };
        let unknowns: Vec<usize> = (0..class.len())
            .filter(|&c| class[c] == CellClass::Unknown)
            .collect();
        let finest = Finest {
            dims,
            class: &|c| class[c],
            unknowns: &unknowns,
            matrix: &a,
        };
        let stats = super::solve(&finest, b, &mut x, &settings);
        assert!(stats.converged, "{stats:?}");
        let mut ax = vec![0.0; a.len()];
        a.apply(&x, &mut ax);
        let r: Vec<f64> = b.iter().zip(&ax).map(|(p, q)| p - q).collect();
        assert!(
            max_abs(&r) <= 1.01 * tolerance * max_abs(b),
            "true residual {r:?}"
        );
        (x, a, stats)
    }

    #[test]
    fn the_finest_level_is_the_system_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D], seed: u64) {
            let mut rng = StdRng::seed_from_u64(seed);
            let class = random_classes(dims.iter().product(), 0.2, 0.2, &mut rng);
            let a = system(dims, &class);
            let mg = multigrid(dims, &class);
            let fine = &mg.levels[0].op;
            let x = random_vector(a.len(), &mut rng);
            let mut ax = vec![0.0; a.len()];
            a.apply(&x, &mut ax);
            // CG's matrix is A, and the level's residual of b = 0 is -A x, in the level's
            // row order.
            let mut xl = vec![0.0; a.len()];
            for (i, &j) in mg.level_row.iter().enumerate() {
                xl[j as usize] = x[i];
            }
            let (mut r, mut out) = (vec![0.0; a.len()], vec![0.0; a.len()]);
            fine.residual(&vec![0.0; a.len()], &xl, &mut r, 0..a.len());
            let x_ax = mg.apply_dot(&xl, &mut out);
            for (i, &j) in mg.level_row.iter().enumerate() {
                assert!((r[j as usize] + ax[i]).abs() <= 1e-12, "row {i}");
                assert!((out[j as usize] - ax[i]).abs() <= 1e-12, "row {i}");
            }
            assert!((x_ax - dot(&x, &ax)).abs() <= 1e-9 * x_ax.abs(), "{x_ax}");
        }
        check([23, 17], 1);
        check([9, 8, 7], 2);
    }

    /// The next coarser grid's classes and open faces' bits of every cell, by the module
    /// doc's rule, from every cell of the finer grid's (the whole grid, as the hierarchy was
    /// built before it kept only the cells near the rows).
    fn coarsen_every_cell<const D: usize>(
        fine: &Shape<D>,
        class: &[CellClass],
        open: &[u8],
    ) -> (Vec<CellClass>, Vec<u8>) {
        let coarse = fine.coarser();
        (0..coarse.cells())
            .map(|k| {
                let kc = coords(&coarse.dims, k);
                let (mut c, mut o) = (CellClass::Neumann, 0);
                for mask in 0..1usize << D {
                    let fc: [usize; D] = std::array::from_fn(|a| 2 * kc[a] + (mask >> a & 1));
                    if (0..D).all(|a| fc[a] < fine.dims[a]) {
                        let f = fine.index(fc);
                        c = coarser_class(c, class[f]);
                        o |= open[f] & mask as u8;
                    }
                }
                (c, o)
            })
            .unzip()
    }

    /// Every cell's class and open faces on every level of the hierarchy, kept or worked out
    /// from the finest cells, are those of coarsening every cell of every level; the levels
    /// keep some cells and not others. The liquid is a pool in the lower third with air pockets
    /// and a few drops above it, among solid cells sprinkled everywhere, so that far cells
    /// (air, solid and mixed blocks) sit beside kept ones on every level.
    #[test]
    fn kept_and_far_cells_are_those_of_coarsening_every_cell_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D], seed: u64) {
            let mut rng = StdRng::seed_from_u64(seed);
            let class: Vec<CellClass> = (0..dims.iter().product())
                .map(|i| {
                    let height = coords(&dims, i)[D - 1];
                    let (low, high) = (3 * height < dims[D - 1], 2 * height >= dims[D - 1]);
                    match rng.random::<f64>() {
                        u if u < 0.2 => CellClass::Neumann,
                        _ if high && i % 50 == 0 => CellClass::Unknown,
                        u if !high && (u < 0.3 || (low && u < 0.97)) => CellClass::Unknown,
                        _ => CellClass::Dirichlet,
                    }
                })
                .collect();
            let unknowns: Vec<usize> = (0..class.len())
                .filter(|&c| class[c] == CellClass::Unknown)
                .collect();
            let matrix = system(dims, &class);
            let finest = Finest {
                dims,
                class: &|c| class[c],
                unknowns: &unknowns,
                matrix: &matrix,
            };
            let mut shape = Shape::new(dims);
            let open: Vec<u8> = (0..class.len())
                .map(|i| {
                    let c = coords(&dims, i);
                    let wet = |i: usize| class[i] != CellClass::Neumann;
                    (0..D)
                        .filter(|&a| c[a] + 1 < dims[a] && wet(i) && wet(i + shape.stride[a]))
                        .fold(0, |o, a| o | 1 << a)
                })
                .collect();
            let (mut every_class, mut every_open) = (class.clone(), open);
            let mut cells = Cells::finest(&finest);
            let mut rows = Operator::finest(&finest).0.at;
            let mut levels = 1;
            while rows.len() > COARSEST_ROWS {
                cells = cells.coarsen(&rows);
                rows = Operator::new(&cells, 1.0).at;
                (every_class, every_open) = coarsen_every_cell(&shape, &every_class, &every_open);
                shape = shape.coarser();
                levels += 1;
                for i in 0..shape.cells() {
                    let c = coords(&shape.dims, i);
                    assert_eq!(cells.class(i), every_class[i], "level {levels} cell {c:?}");
                    for a in 0..D {
                        let want = every_open[i] >> a & 1 == 1;
                        assert_eq!(cells.open(i, c, a), want, "level {levels} {c:?} axis {a}");
                    }
                }
                let kept = cells.code.iter().filter(|&&k| k != 0).count();
                assert!(
                    kept > 0 && kept < shape.cells(),
                    "level {levels}: {kept} kept"
                );
            }
            assert!(levels >= 3, "{levels} levels");
        }
        check([150, 120], 11);
        check([40, 36, 44], 12);
    }

    /// Under a flat free surface, a first-coarse-level row just below it weighs its Dirichlet
    /// neighbour by one over the distance to the finest level's zero: with the liquid 4
    /// finest cells deep, the first empty cell's centre lies 1.5 finest cells (0.75 coarse)
    /// above the centre of coarse layer 1, so 8/0.75 = 10.67 eighths, rounded to 11; 5 deep,
    /// coarse layer 2 is still Dirichlet (its lower child is liquid) and the zero lies 2.5
    /// finest cells (1.25 coarse) up: 6.4, rounded to 6. Its other neighbours (below, and
    /// beside along the other axes) count whole.
    #[test]
    fn a_coarse_dirichlet_neighbour_weighs_one_over_its_distance_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D]) {
            for (depth, weight) in [(4, 11), (5, 6)] {
                let mg = multigrid(dims, &pool(dims, depth));
                let op = &mg.levels[1].op;
                let mut c = [2; D];
                c[D - 1] = 1;
                let row = op.row[op.shape.index(c)] as usize - 1;
                let whole = (2 * (D - 1) + 1) as u8 * EIGHTHS;
                assert_eq!(op.stencil[row].count, whole + weight, "depth {depth}");
            }
        }
        check([80, 16]);
        check([16, 16, 8]);
    }

    /// `A x` on a level, by its residual with `b = 0`.
    /// A pool `depth` cells deep along the last axis of `dims`, air above.
    fn pool<const D: usize>(dims: [usize; D], depth: usize) -> Vec<CellClass> {
        (0..dims.iter().product())
            .map(|c| match coords(&dims, c)[D - 1] < depth {
                true => CellClass::Unknown,
                false => CellClass::Dirichlet,
            })
            .collect()
    }

    #[test]
    fn prolongation_carries_a_linear_profile_to_the_fine_surface_2d_and_3d() {
        // A depth that no coarse level divides: each level's surface sits below the fine one.
        fn check<const D: usize>(dims: [usize; D], depth: usize) {
            let mut mg = multigrid(dims, &pool(dims, depth));
            assert!(mg.levels.len() >= 3, "{} levels", mg.levels.len());
            // Hydrostatic: zero at the finest level's Dirichlet cell centre.
            let u = |y: f64| depth as f64 + 0.5 - y;
            let centre = |k: u16, l: usize| (k as f64 + 0.5) * (1 << l) as f64;
            for l in 1..mg.levels.len() {
                let (fine, coarse) = mg.levels.split_at_mut(l);
                let (fine, coarse) = (&fine[l - 1], &mut coarse[0]);
                coarse.x = (coarse.op.at.iter())
                    .map(|k| u(centre(k[D - 1], l)))
                    .collect();
                let mut x = vec![0.0; fine.op.len()];
                fine.prolong_add(coarse, &mut x);
                // Prolongation adds on the red rows only (`prolong_add`); rows next to a
                // wall take their parent's value there (a no-flux mirror), not the profile.
                let free = |i: usize| fine.movable[i] == (1 << D) - 1 && fine.to_parent[i] == 0.0;
                for i in (0..fine.op.red).filter(|&i| free(i)) {
                    let exact = u(centre(fine.op.at[i][D - 1], l - 1));
                    // The coarse Dirichlet distances are kept in eighths of a weight.
                    assert!(
                        (x[i] - exact).abs() <= 0.05 * u(0.0),
                        "level {l}, row at {:?}: {} against {exact}",
                        fine.op.at[i],
                        x[i]
                    );
                }
            }
        }
        check([128, 32], 15);
        check([32, 32, 32], 15);
    }

    #[test]
    fn a_pool_of_any_depth_keeps_its_last_layer_and_its_iterations_3d() {
        // 160 x 160 cells: the layer left on level 3 (400 rows) vanishes on level 4 at depth
        // 15, not at 16.
        let dims = [160, 160, 32];
        let iterations = |depth: usize| {
            let class = pool(dims, depth);
            let mg = multigrid(dims, &class);
            let coarsest = mg.levels.last().expect("a level").op.len();
            let b = vec![1.0; mg.level_row.len()];
            (coarsest, solve(dims, &class, &b, 1e-9).2.iterations)
        };
        let ((rows15, it15), (rows16, it16)) = (iterations(15), iterations(16));
        assert_eq!(rows15, 400, "the coarsest level keeps the last layer");
        assert!(rows16 <= COARSEST_ROWS, "{rows16}");
        assert!(it15 <= it16, "depth 15: {it15} iterations, 16: {it16}");
    }

    fn apply_level<const D: usize>(op: &Operator<D>, x: &[f64]) -> Vec<f64> {
        let mut r = vec![0.0; op.len()];
        op.residual(&vec![0.0; op.len()], x, &mut r, 0..op.len());
        r.iter().map(|r| -r).collect()
    }

    /// On a closed box whose sides are no powers of two, every coarse level has cells cut by
    /// the grid's upper walls. Its operator must still be a finite-volume Laplacian of the
    /// cells as they are: taking the centroids' coordinate along an axis, a uniform gradient,
    /// to the flux through each wall face (the face's area, 0 inside), and staying symmetric.
    /// With whole-cell weights the last cell's centroid sits half a cut nearer than the
    /// operator assumes, and the first check fails (on a half-full tank of 65^3 cells the
    /// PCG iterations were 14 against 9 at 64^3; docs/benchmarks/pressure.md).
    #[test]
    fn a_coarse_level_with_cut_cells_keeps_a_uniform_gradient_and_its_symmetry_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D]) {
            let class = vec![CellClass::Unknown; dims.iter().product()];
            let mg = multigrid(dims, &class);
            assert!(mg.levels.len() >= 3, "{} levels", mg.levels.len());
            for (l, level) in mg.levels.iter().enumerate().skip(1) {
                let (op, side) = (&level.op, 1usize << l);
                let extent = |k: usize, a: usize| {
                    (dims[a].min((k + 1) * side) - k * side) as f64 / side as f64
                };
                assert!(
                    (0..D).any(|a| extent(op.shape.dims[a] - 1, a) < 1.0),
                    "level {l}"
                );
                for a in 0..D {
                    let centroid: Vec<f64> = (op.at.iter().map(|c| widen(*c)))
                        .map(|c| c[a] as f64 + extent(c[a], a) / 2.0)
                        .collect();
                    let flux = apply_level(op, &centroid);
                    for (i, c) in op.at.iter().map(|c| widen(*c)).enumerate() {
                        let area: f64 = (0..D)
                            .filter(|&b| b != a)
                            .map(|b| extent(c[b], b))
                            .product();
                        let walls = (c[a] == 0) as i32 - (c[a] + 1 == op.shape.dims[a]) as i32;
                        let want = -op.scale * area * walls as f64;
                        assert!(
                            (flux[i] - want).abs() < 1e-12,
                            "level {l} axis {a} cell {c:?}: {} against {want}",
                            flux[i]
                        );
                    }
                }
                let n = op.len();
                let columns: Vec<Vec<f64>> = (0..n)
                    .map(|j| {
                        apply_level(
                            op,
                            &(0..n).map(|k| (k == j) as u8 as f64).collect::<Vec<_>>(),
                        )
                    })
                    .collect();
                for i in 0..n {
                    for j in 0..i {
                        assert!(
                            (columns[j][i] - columns[i][j]).abs() < 1e-12,
                            "level {l}: rows {i}, {j}"
                        );
                    }
                }
            }
        }
        check([75, 45]);
        check([29, 23, 13]);
    }

    #[test]
    fn restriction_is_the_transpose_of_prolongation_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D], seed: u64) {
            let mut rng = StdRng::seed_from_u64(seed);
            let class = random_classes(dims.iter().product(), 0.25, 0.2, &mut rng);
            let mut mg = multigrid(dims, &class);
            assert!(mg.levels.len() >= 3, "{} levels", mg.levels.len());
            let (mut loose, mut rows, mut ghosts) = (0, 0, 0);
            for l in 0..mg.levels.len() - 1 {
                let (fine, coarse) = mg.levels.split_at_mut(l + 1);
                let (fine, coarse) = (&mut fine[l], &mut coarse[0]);
                let cop = &coarse.op;
                loose += (cop.at.iter())
                    .filter(|&&k| fine.loose[cop.shape.index(widen(k))])
                    .count();
                rows += cop.len();
                ghosts += cop.ghosts.len();
                // As the V-cycle's residuals: zero on the coupled black rows, where
                // prolongation skips (`residual_after_black`, `prolong_add`).
                fine.r = random_vector(fine.r.len(), &mut rng);
                for i in fine.op.red..fine.r.len() {
                    if fine.op.lonely.binary_search(&(i as u32)).is_err() {
                        fine.r[i] = 0.0;
                    }
                }
                coarse.x = random_vector(coarse.x.len(), &mut rng);
                fine.restrict(coarse);
                let mut fine_x = vec![0.0; fine.op.len()];
                fine.prolong_add(coarse, &mut fine_x);
                let (rt, pt) = (dot(&coarse.x, &coarse.b), dot(&fine_x, &fine.r));
                assert!((rt - pt).abs() <= 1e-12 * rt.abs().max(1.0), "{rt} {pt}");
            }
            // Both ways of restricting are taken, and Dirichlet cells extrapolated into.
            assert!(
                loose > 0 && loose < rows && ghosts > 0,
                "{loose} loose of {rows} coarse rows, {ghosts} ghosts"
            );
        }
        check([70, 61], 3);
        check([21, 18, 23], 4);
    }

    /// After pre-smoothing, the residual the V-cycle takes (`residual_after_black`) is the
    /// full one to rounding, on every level, lonely rows included (solid cells sprinkled
    /// densely enough to isolate some fluid cells).
    #[test]
    fn the_residual_after_pre_smoothing_is_the_full_one_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D], seed: u64) {
            let mut rng = StdRng::seed_from_u64(seed);
            let class = random_classes(dims.iter().product(), 0.4, 0.1, &mut rng);
            let mut mg = multigrid(dims, &class);
            assert!(mg.levels.len() >= 2, "{} levels", mg.levels.len());
            assert!(!mg.levels[0].op.lonely.is_empty(), "no lonely black row");
            for level in &mut mg.levels {
                let n = level.op.len();
                let (b, mut x) = (random_vector(n, &mut rng), random_vector(n, &mut rng));
                level.pre_smooth(&b, &mut x);
                let mut full = vec![0.0; n];
                level.op.residual(&b, &x, &mut full, 0..n);
                level.op.residual_after_black(&b, &x, &mut level.r);
                let size = max_abs(&b);
                for i in 0..n {
                    assert!((full[i] - level.r[i]).abs() <= 1e-12 * size, "row {i}");
                }
            }
        }
        check([60, 50], 21);
        check([20, 18, 16], 22);
    }

    /// `x^T B y = y^T B x` to rounding and `x^T B x > 0` on random masks (with closed
    /// pockets among the solids), `B` the V-cycle. The empty cells lie in the upper half
    /// of the last axis, as above a free surface: sprinkled all over, they would make
    /// nearly every coarse cell Dirichlet and leave too few levels to test.
    fn symmetric_positive_definite<const D: usize>(dims: [usize; D], seeds: std::ops::Range<u64>) {
        for seed in seeds {
            let mut rng = StdRng::seed_from_u64(seed);
            let air = [0.0, 0.05, 0.3][seed as usize % 3];
            let mut class = random_classes(dims.iter().product(), 0.2, air, &mut rng);
            for (c, class) in class.iter_mut().enumerate() {
                if *class == CellClass::Dirichlet && 2 * coords(&dims, c)[D - 1] < dims[D - 1] {
                    *class = CellClass::Unknown;
                }
            }
            let mut mg = multigrid(dims, &class);
            assert!(mg.levels.len() >= 3, "{} levels", mg.levels.len());
            let n = mg.level_row.len();
            let (x, y) = (random_vector(n, &mut rng), random_vector(n, &mut rng));
            let (mut bx, mut by) = (vec![0.0; n], vec![0.0; n]);
            mg.precondition(&x, &mut bx);
            mg.precondition(&y, &mut by);
            let (ybx, xby) = (dot(&y, &bx), dot(&x, &by));
            let size = dot(&x, &bx).abs().max(dot(&y, &by).abs());
            assert!(
                (ybx - xby).abs() <= 1e-12 * size,
                "seed {seed}: {ybx} vs {xby}"
            );
            assert!(dot(&x, &bx) > 0.0 && dot(&y, &by) > 0.0, "seed {seed}");
        }
    }

    #[test]
    fn the_v_cycle_is_symmetric_positive_definite_2d() {
        symmetric_positive_definite([64, 48], 0..6);
    }

    #[test]
    fn the_v_cycle_is_symmetric_positive_definite_3d() {
        symmetric_positive_definite([20, 17, 22], 10..16);
    }

    /// A known solution on random fluid, air and solid cells, solved to the tolerance; the
    /// error is checked where it is determined: pressure differences between neighbours,
    /// and values next to a Dirichlet cell (a closed pocket only up to a constant).
    fn manufactured<const D: usize>(dims: [usize; D], seed: u64) {
        let mut rng = StdRng::seed_from_u64(seed);
        let class = random_classes(dims.iter().product(), 0.15, 0.1, &mut rng);
        let exact = random_vector(
            class.iter().filter(|&&c| c == CellClass::Unknown).count(),
            &mut rng,
        );
        let a = system(dims, &class);
        let mut b = vec![0.0; a.len()];
        a.apply(&exact, &mut b);
        let (x, a, _) = solve(dims, &class, &b, 1e-10);
        let e: Vec<f64> = x.iter().zip(&exact).map(|(p, q)| p - q).collect();
        for r in 0..a.len() {
            let linked = a.plus[r].iter().filter(|&&p| p != NONE).count();
            let neighbours = linked + a.minus[r].iter().filter(|&&m| m != NONE).count();
            if (a.diag[r] as usize) > neighbours {
                assert!(e[r].abs() < 1e-6, "row {r}: error {}", e[r]);
            }
            for &p in a.plus[r].iter().filter(|&&p| p != NONE) {
                assert!((e[r] - e[p as usize]).abs() < 1e-6, "rows {r}, {p}");
            }
        }
    }

    #[test]
    fn solves_a_manufactured_solution_with_air_and_solids_2d() {
        manufactured([72, 56], 5);
    }

    #[test]
    fn solves_a_manufactured_solution_with_air_and_solids_3d() {
        manufactured([24, 20, 22], 6);
    }

    /// A closed tank full of fluid around a solid block: no Dirichlet cell at all, a singular
    /// system whose right-hand side has zero mean.
    fn closed_region<const D: usize>(dims: [usize; D]) {
        let class: Vec<CellClass> = (0..dims.iter().product())
            .map(|c| {
                let cc = coords(&dims, c);
                match (0..D).all(|a| cc[a] >= dims[a] / 3 && cc[a] < dims[a] / 2) {
                    true => CellClass::Neumann,
                    false => CellClass::Unknown,
                }
            })
            .collect();
        let mut rng = StdRng::seed_from_u64(7);
        let mut b = random_vector(
            class.iter().filter(|&&c| c == CellClass::Unknown).count(),
            &mut rng,
        );
        let mean = b.iter().sum::<f64>() / b.len() as f64;
        b.iter_mut().for_each(|v| *v -= mean);
        let (_, _, stats) = solve(dims, &class, &b, 1e-9);
        assert!(stats.iterations <= 30, "{stats:?}");
    }

    #[test]
    fn solves_a_closed_region_2d() {
        closed_region([64, 64]);
    }

    #[test]
    fn solves_a_closed_region_3d() {
        closed_region([24, 24, 24]);
    }

    /// A one-cell-wide channel winding through solid rows (walls one cell thick, so coarse
    /// cells straddle neighbouring turns), open to air at its start, with a known solution.
    fn channel<const D: usize>(dims: [usize; D]) {
        let class: Vec<CellClass> = (0..dims.iter().product())
            .map(|c| {
                let cc = coords(&dims, c);
                let (x, y) = (cc[0], cc[1]);
                let deep = (2..D).all(|a| cc[a] == dims[a] / 2);
                let turn = (y % 4 == 1 && x == dims[0] - 1) || (y % 4 == 3 && x == 0);
                match (deep && (y % 2 == 0 || turn), x == 0 && y == 0) {
                    (true, true) => CellClass::Dirichlet,
                    (true, false) => CellClass::Unknown,
                    (false, _) => CellClass::Neumann,
                }
            })
            .collect();
        let a = system(dims, &class);
        assert!(a.len() > 4 * COARSEST_ROWS);
        let mut rng = StdRng::seed_from_u64(8);
        let exact = random_vector(a.len(), &mut rng);
        let mut b = vec![0.0; a.len()];
        a.apply(&exact, &mut b);
        let (x, _, stats) = solve(dims, &class, &b, 1e-12);
        // Coarse faces closed along the walls keep the turns apart (about 470 iterations
        // without them).
        assert!(stats.iterations <= 250, "{stats:?}");
        let err = x
            .iter()
            .zip(&exact)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        // The channel's matrix has condition number ~ its length squared.
        assert!(err < 1e-4, "error {err}");
    }

    #[test]
    fn solves_a_one_cell_wide_channel_2d() {
        channel([64, 64]);
    }

    #[test]
    fn solves_a_one_cell_wide_channel_3d() {
        channel([48, 48, 3]);
    }

    /// One fluid cell alone: among empty cells its pressure is `b / 2D`; among solid cells
    /// its row is zero (closed), its right-hand side too, and any finite value solves it.
    /// Beside a pool, so that the hierarchy has several levels.
    fn isolated_cell<const D: usize>(dims: [usize; D], around: CellClass) {
        let centre: [usize; D] = std::array::from_fn(|a| dims[a] / 2);
        let c0 = Shape::new(dims).index(centre);
        let class: Vec<CellClass> = (0..dims.iter().product())
            .map(|c| {
                let cc = coords(&dims, c);
                let near = (0..D).all(|a| cc[a].abs_diff(centre[a]) <= 1);
                match (c == c0, near, cc[D - 1] < dims[D - 1] / 4) {
                    (true, _, _) => CellClass::Unknown,
                    (false, true, _) => around,
                    (false, false, true) => CellClass::Unknown,
                    _ => CellClass::Dirichlet,
                }
            })
            .collect();
        let row = (0..c0).filter(|&c| class[c] == CellClass::Unknown).count();
        let n = row
            + 1
            + (c0 + 1..class.len())
                .filter(|&c| class[c] == CellClass::Unknown)
                .count();
        let mut b = vec![1.0; n];
        let closed = around == CellClass::Neumann;
        b[row] = if closed { 0.0 } else { 3.0 };
        assert!(multigrid(dims, &class).levels.len() >= 2);
        let (x, _, _) = solve(dims, &class, &b, 1e-9);
        let want = 3.0 / (2 * D) as f64;
        match closed {
            true => assert!(x[row].is_finite()),
            false => assert!((x[row] - want).abs() <= 1e-8, "{} vs {want}", x[row]),
        }
    }

    #[test]
    fn solves_a_single_isolated_fluid_cell_2d_and_3d() {
        for around in [CellClass::Dirichlet, CellClass::Neumann] {
            isolated_cell([40, 40], around);
            isolated_cell([16, 16, 16], around);
        }
    }

    /// A dam-like tank: a fluid column `0.4 x 0.8` of the tank's width and height plus a
    /// shallow pool, air above, a random right-hand side. Returns the iterations with
    /// multigrid and with MIC(0).
    fn dam_iterations(n: usize) -> (usize, usize) {
        let dims = [n; 3];
        let class: Vec<CellClass> = (0..n * n * n)
            .map(|c| {
                let [x, y, _] = coords(&dims, c);
                match (5 * x < 2 * n && 5 * y < 4 * n) || 10 * y < n {
                    true => CellClass::Unknown,
                    false => CellClass::Dirichlet,
                }
            })
            .collect();
        let a = system(dims, &class);
        let b = random_vector(a.len(), &mut StdRng::seed_from_u64(9));
        let (_, _, mg) = solve(dims, &class, &b, 1e-9);
        let mut x = vec![0.0; a.len()];
        let mic = pcg::solve(&a, &b, &mut x, &PcgSettings::default());
        assert!(mic.converged);
        (mg.iterations, mic.iterations)
    }

    #[test]
    fn multigrid_iterations_stay_nearly_constant_in_3d_while_mic0_grows() {
        let (mg32, mic32) = dam_iterations(32);
        let (mg64, mic64) = dam_iterations(64);
        let counts = format!("multigrid {mg32} -> {mg64}, MIC(0) {mic32} -> {mic64}");
        assert!(mg32 <= 30 && mg64 <= 30, "{counts}");
        assert!(2 * mg64 <= 3 * mg32, "{counts}");
        assert!(mic64 > mic32 && mg64 < mic64, "{counts}");
    }
}
