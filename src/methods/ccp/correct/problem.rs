//! The correction problem of paper eq. problem3, built once per step as plain data that both
//! solvers read.
//!
//! Each particle `j` may end in the cell of its previous position `x_bar_j` moved by one of the
//! directions `D` (sec. grid_move, eq. directions); in that cell it sits at
//! `xi_ij = phi_close(x_hat_j, cell)`, the point closest to its ideal position with the margin
//! epsilon (eq. best_cell_pos), at cost `sigma_obj = |xi_ij - x_hat_j|^2`. Cell bounds use the
//! markings of the previous iteration: empty and surface cells hold at most `mu` (eq.
//! problem3.d), inner cells between their previous count and `mu` (eq. problem3.e), solid cells
//! nothing (eq. problem3.f: their candidates are dropped, as are those outside the domain).
//!
//! With the band method (sec. band_con) the bounds follow eq. band_con_update instead: the band
//! interface may lose particles like the surface, the rest of the band keeps its count, and the
//! deep holds at most `mu` (see [`cell_bounds`]). Each candidate then also says
//! whether it moves a particle into the interface-and-deep region `C_<=-R` or out of it (the sets
//! `gamma_in` and `gamma_out` of eq. band_con).

use crate::grid::active::{Active, CellNumbers};
use crate::grid::{closest_along, Cell, Grid, Vector};
use crate::solvers::min_cost_flow::BoundedAssignment;
use crate::stages::advect::CELL_MARGIN;
use crate::stages::markings::{CellKind, DepthLevel, Markings};
use crate::PAR_GRAIN_PARTICLES;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// The candidate moves of a particle (sec. grid_move; the flag `--directions` names them:
/// `super::super::settings`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Directions {
    /// The paper's: the cell itself and its 2 D face neighbours.
    VonNeumann,
    /// The cell itself and its 3^D - 1 neighbours.
    Moore,
}

impl Directions {
    /// The offsets, staying first (so that ties keep a particle where it was).
    pub fn offsets<const D: usize>(self) -> Vec<[i64; D]> {
        let mut out = vec![[0i64; D]];
        match self {
            Directions::VonNeumann => {
                for a in 0..D {
                    for s in [1, -1] {
                        let mut o = [0; D];
                        o[a] = s;
                        out.push(o);
                    }
                }
            }
            Directions::Moore => {
                for code in 0..3usize.pow(D as u32) {
                    let mut m = code;
                    let o: [i64; D] = std::array::from_fn(|_| {
                        let v = (m % 3) as i64 - 1;
                        m /= 3;
                        v
                    });
                    if o != [0; D] {
                        out.push(o);
                    }
                }
            }
        }
        out
    }
}

/// Eq. problem3 for one step.
#[derive(Clone, Debug)]
pub struct CorrectionProblem<const D: usize> {
    /// Items are particles, bins are cells that some candidate reaches.
    pub assignment: BoundedAssignment,
    /// Grid cell of each bin.
    pub bin_cell: Vec<usize>,
    /// Index of the "stay" candidate of each particle (its cell of `x_bar`).
    pub stay: Vec<u32>,
    /// With the band: per candidate, +1 if it is in `gamma_in` (from `C_>-R` into `C_<=-R`),
    /// -1 if in `gamma_out` (the reverse), 0 otherwise. Empty without the band.
    pub band_sign: Vec<i8>,
}

/// The load bounds `[lower, upper]` of cell `c` in the correction, from the previous markings:
/// eq. problem3.d-e, or eq. band_con_update with the band parameter `band_r`. An upper bound is
/// never below the previous count, so staying put is always feasible.
///
/// The paper leaves deep cells unbounded, since their particles are deleted after the step. We
/// bound them by `mu` like the interface: the new markings can turn a deep cell into an
/// interface cell, whose particles stay, and it must not hold more than `mu` then.
pub fn cell_bounds(previous: &Markings, c: usize, mu: u32, band_r: Option<u32>) -> (u32, u32) {
    let prev = previous.count[c];
    let upper = mu.max(prev);
    if previous.kind[c] != CellKind::Fluid {
        return (0, upper);
    }
    match band_r.map(|r| previous.level(c, r)) {
        None if previous.surface[c] => (0, upper),
        None => (prev, upper),
        Some(DepthLevel::Band) => (prev, upper),
        Some(_) => (0, upper),
    }
}

impl<const D: usize> CorrectionProblem<D> {
    /// `xi` of candidate `k` for a particle advected to `x_hat`: the point of the candidate's
    /// cell closest to `x_hat`, epsilon inside (eq. best_cell_pos).
    pub fn position(&self, grid: &Grid<D>, k: usize, x_hat: &Vector<D>) -> Vector<D> {
        let cell = self.bin_cell[self.assignment.cand_bin[k] as usize];
        grid.closest_in_cell(x_hat, grid.cell_coords(cell), CELL_MARGIN)
    }
}

/// A problem that cannot be built: a bug upstream, reported with the particle.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("particle {particle}: {reason}")]
pub struct BuildError {
    pub particle: usize,
    pub reason: String,
}

/// A particle's home cell (of `x_bar`), its index, and which moves keep it in the domain and
/// out of solids: bit `i` for offset `i`.
#[derive(Clone, Copy)]
struct Moves<const D: usize> {
    home: Cell<D>,
    index: usize,
    allowed: u32,
}

/// The moves' cell offsets, as coordinates and as steps of the cell index (valid for moves
/// that stay in the grid), computed once per problem.
struct MoveOffsets<const D: usize> {
    coords: Vec<[i64; D]>,
    steps: Vec<isize>,
}

impl<const D: usize> MoveOffsets<D> {
    fn new(grid: &Grid<D>, directions: Directions) -> Self {
        let coords = directions.offsets::<D>();
        let step = |o: &[i64; D]| -> isize {
            (0..D)
                .map(|k| o[k] as isize * grid.cell_stride(k) as isize)
                .sum()
        };
        let steps = coords.iter().map(step).collect();
        Self { coords, steps }
    }
}

/// Checks particle `j`'s positions and finds its allowed moves; the stay move must be one.
fn particle_moves<const D: usize>(
    grid: &Grid<D>,
    solid: &[bool],
    offsets: &MoveOffsets<D>,
    j: usize,
    (xb, xh): (&Vector<D>, &Vector<D>),
) -> Result<Moves<D>, BuildError> {
    let err = |reason: String| BuildError {
        particle: j,
        reason,
    };
    if !xh.iter().all(|v| v.is_finite()) {
        let at = xh.as_slice();
        return Err(err(format!("advected position {at:?} is not finite")));
    }
    let Some(home) = grid.cell_of(xb) else {
        let at = xb.as_slice();
        return Err(err(format!(
            "previous position {at:?} is outside the domain"
        )));
    };
    if !grid.contains(xh) {
        let at = xh.as_slice();
        return Err(err(format!(
            "advected position {at:?} is outside the domain"
        )));
    }
    let index = grid.cell_index(home);
    // Away from the domain's walls every move stays in the grid.
    let inner = (0..D).all(|k| home[k] >= 1 && home[k] + 1 < grid.dims[k]);
    let mut allowed = 0;
    for (i, (o, &step)) in offsets.coords.iter().zip(&offsets.steps).enumerate() {
        let stays = inner || offset_cell(grid, home, o).is_some();
        if stays && !solid[index.wrapping_add_signed(step)] {
            allowed |= 1 << i;
        }
    }
    if allowed & 1 == 0 {
        return Err(err(format!("its previous cell {home:?} is solid")));
    }
    Ok(Moves {
        home,
        index,
        allowed,
    })
}

fn offset_cell<const D: usize>(grid: &Grid<D>, c: Cell<D>, o: &[i64; D]) -> Option<Cell<D>> {
    let mut out = c;
    for k in 0..D {
        let v = c[k] as i64 + o[k];
        if v < 0 || v >= grid.dims[k] as i64 {
            return None;
        }
        out[k] = v as usize;
    }
    Some(out)
}

/// The cell a move of `m` by offset `o` leads to, which stays in the grid.
fn moved<const D: usize>(m: &Moves<D>, o: &[i64; D]) -> Cell<D> {
    std::array::from_fn(|k| m.home[k].wrapping_add_signed(o[k] as isize))
}

/// The allowed moves of `m`, in order: each offset with the index of the cell it leads to.
fn allowed<'a, const D: usize>(
    m: &Moves<D>,
    offsets: &'a MoveOffsets<D>,
) -> impl Iterator<Item = (&'a [i64; D], usize)> {
    let (bits, index) = (m.allowed, m.index);
    let moves = offsets.coords.iter().zip(&offsets.steps).enumerate();
    moves
        .filter(move |(i, _)| bits >> i & 1 == 1)
        .map(move |(_, (o, &step))| (o, index.wrapping_add_signed(step)))
}

/// Items per parallel task when packing candidates.
const ITEM_BLOCK: usize = 2048;

/// `out` cut into the candidate ranges of consecutive blocks of [`ITEM_BLOCK`] items.
fn block_pieces<'a, T>(mut out: &'a mut [T], item_start: &[usize]) -> Vec<&'a mut [T]> {
    let items = item_start.len() - 1;
    let mut pieces = Vec::with_capacity(items.div_ceil(ITEM_BLOCK));
    for first in (0..items).step_by(ITEM_BLOCK) {
        let len = item_start[(first + ITEM_BLOCK).min(items)] - item_start[first];
        let (piece, rest) = std::mem::take(&mut out).split_at_mut(len);
        pieces.push(piece);
        out = rest;
    }
    pieces
}

/// Builds eq. problem3 from the previous positions `x_bar`, the advected positions `x_hat`, the
/// previous markings (with counts `|gamma_bar_c|`) and the current solid cells, with the band's
/// bounds and in/out signs when `band_r` is given. With `penalty` (per cell, > 0 on the cells
/// an obstacle wants, `C_new_solid`) a candidate there costs the penalty instead of its
/// distance: `sigma_solid_obj` of eq. solid_penalty2. `x_bar` is always feasible.
///
/// Every pass but the numbering of the bins runs in parallel, and the result does not depend
/// on the thread count.
#[allow(clippy::too_many_arguments)]
pub fn build<const D: usize>(
    grid: &Grid<D>,
    x_bar: &[Vector<D>],
    x_hat: &[Vector<D>],
    previous: &Markings,
    solid: &[bool],
    mu: u32,
    directions: Directions,
    band_r: Option<u32>,
    penalty: Option<&[f64]>,
) -> Result<CorrectionProblem<D>, BuildError> {
    let offsets = MoveOffsets::new(grid, directions);
    // A particle with no allowed move is one in error; the first is reported.
    let moves: Vec<Moves<D>> = (x_bar.par_iter().zip(x_hat).enumerate())
        .with_min_len(PAR_GRAIN_PARTICLES)
        .map(|(j, x)| {
            particle_moves(grid, solid, &offsets, j, x).unwrap_or(Moves {
                home: [0; D],
                index: 0,
                allowed: 0,
            })
        })
        .collect();
    if let Some(j) = moves.iter().position(|m| m.allowed == 0) {
        let x = (&x_bar[j], &x_hat[j]);
        particle_moves(grid, solid, &offsets, j, x)?;
    }
    // Every move ends within one cell of the particle's previous cell.
    let near = Active::around_points(grid, x_bar.par_iter(), 1).numbers(grid);
    let (bin_cell, bin_of) = number_bins(&moves, &offsets, &near);
    let (lower, upper) = bin_cell
        .par_iter()
        .map(|&c| cell_bounds(previous, c, mu, band_r))
        .unzip();
    let mut item_start = Vec::with_capacity(moves.len() + 1);
    item_start.push(0);
    for m in &moves {
        item_start.push(item_start.last().expect("starts at 0") + m.allowed.count_ones() as usize);
    }
    let n = item_start[moves.len()];
    let (mut cand_bin, mut cand_cost) = (vec![0u32; n], vec![0.0; n]);
    let mut band_sign = vec![0i8; if band_r.is_some() { n } else { 0 }];
    let low = |c: usize| band_r.is_some_and(|r| previous.at_or_below_interface(c, r));
    let sign_pieces: Vec<&mut [i8]> = match band_r {
        Some(_) => block_pieces(&mut band_sign, &item_start),
        None => std::iter::repeat_with(Default::default)
            .take(moves.len().div_ceil(ITEM_BLOCK))
            .collect(),
    };
    let pieces = block_pieces(&mut cand_bin, &item_start).into_par_iter();
    let pieces = pieces.zip(block_pieces(&mut cand_cost, &item_start));
    let blocks = pieces.zip(sign_pieces).zip(moves.par_chunks(ITEM_BLOCK));
    blocks
        .enumerate()
        .for_each(|(b, (((bins, costs), signs), block))| {
            let mut k = 0;
            for (j, m) in block.iter().enumerate() {
                let xh = &x_hat[b * ITEM_BLOCK + j];
                let home_low = low(m.index);
                // `|phi_close(x_hat, c) - x_hat|^2` summed axis by axis, each axis's term for the
                // home cell's coordinate shifted by -1, 0 and +1.
                let gap: [[f64; 3]; D] = std::array::from_fn(|a| {
                    std::array::from_fn(|s| match (m.home[a] + s).checked_sub(1) {
                        Some(c) => (closest_along(xh[a], c, CELL_MARGIN) - xh[a]).powi(2),
                        None => f64::NAN,
                    })
                });
                for (o, ci) in allowed(m, &offsets) {
                    bins[k] = bin_of[near.at(moved(m, o)).expect("a cell near x_bar")];
                    costs[k] = match penalty.map(|p| p[ci]) {
                        Some(p) if p > 0.0 => p,
                        _ => (0..D).map(|a| gap[a][(o[a] + 1) as usize]).sum(),
                    };
                    if let Some(s) = signs.get_mut(k) {
                        *s = match (home_low, low(ci)) {
                            (false, true) => 1,
                            (true, false) => -1,
                            _ => 0,
                        };
                    }
                    k += 1;
                }
            }
        });
    Ok(CorrectionProblem {
        stay: item_start[..moves.len()]
            .iter()
            .map(|&k| k as u32)
            .collect(),
        assignment: BoundedAssignment {
            item_start,
            cand_bin,
            cand_cost,
            lower,
            upper,
        },
        bin_cell,
        band_sign,
    })
}

/// The bins: the cells that candidates reach, numbered in cell order so that neighbouring
/// cells are near in memory (the solver's searches walk from cells to their neighbours).
/// Returns the cell of each bin and the bin of each cell numbered by `near` (`u32::MAX` for
/// none), which numbers every cell a move reaches.
fn number_bins<const D: usize>(
    moves: &[Moves<D>],
    offsets: &MoveOffsets<D>,
    near: &CellNumbers,
) -> (Vec<usize>, Vec<u32>) {
    let reached: Vec<AtomicBool> = (0..near.len()).map(|_| AtomicBool::new(false)).collect();
    moves
        .par_iter()
        .with_min_len(PAR_GRAIN_PARTICLES)
        .for_each(|m| {
            for (o, _) in allowed(m, offsets) {
                let k = near.at(moved(m, o)).expect("a cell near x_bar");
                reached[k].store(true, Ordering::Relaxed);
            }
        });
    let mut bin_cell = vec![];
    let mut cells = near.cells();
    let bin_of = reached
        .iter()
        .zip(&mut cells)
        .map(|(r, c)| {
            if !r.load(Ordering::Relaxed) {
                return u32::MAX;
            }
            bin_cell.push(c);
            bin_cell.len() as u32 - 1
        })
        .collect();
    (bin_cell, bin_of)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn direction_sets_have_the_paper_sizes() {
        assert_eq!(Directions::VonNeumann.offsets::<2>().len(), 5);
        assert_eq!(Directions::VonNeumann.offsets::<3>().len(), 7);
        assert_eq!(Directions::Moore.offsets::<2>().len(), 9);
        assert_eq!(Directions::Moore.offsets::<3>().len(), 27);
    }

    #[test]
    fn candidates_bounds_and_costs_follow_eq_problem3() {
        // 4x4 grid, mu = 1. Particle 0 in cell (1,1), advected to (2.5, 1.5) inside cell (2,1).
        // Particle 1 sits in (0,0) and stays. Cell (1,2) is solid.
        let g = Grid::new([4, 4]);
        let x_bar = vec![Vector::<2>::new(1.5, 1.5), Vector::<2>::new(0.5, 0.5)];
        let x_hat = vec![Vector::<2>::new(2.5, 1.5), Vector::<2>::new(0.5, 0.5)];
        let mut solid = vec![false; 16];
        solid[g.cell_index([1, 2])] = true;
        let prev = Markings::compute(&g, &x_bar, &solid);
        let p = build(
            &g,
            &x_bar,
            &x_hat,
            &prev,
            &solid,
            1,
            Directions::VonNeumann,
            None,
            None,
        )
        .unwrap();
        let a = &p.assignment;
        // Particle 0: stay, +x, -x, -y (+y is solid): 4 candidates. Particle 1: stay, +x, +y.
        assert_eq!(a.candidates(0).len(), 4);
        assert_eq!(a.candidates(1).len(), 3);
        // Its stay candidate is the closest point of cell (1,1) to x_hat, epsilon inside.
        let s = p.stay[0] as usize;
        assert!(
            (p.position(&g, s, &x_hat[0]) - Vector::<2>::new(2.0 - CELL_MARGIN, 1.5)).norm()
                < 1e-12
        );
        assert!((a.cand_cost[s] - (0.5 + CELL_MARGIN).powi(2)).abs() < 1e-12);
        // The +x candidate is x_hat itself, at zero cost.
        let best = a
            .candidates(0)
            .min_by(|&i, &j| a.cand_cost[i].total_cmp(&a.cand_cost[j]))
            .unwrap();
        assert_eq!(a.cand_cost[best], 0.0);
        assert_eq!(p.bin_cell[a.cand_bin[best] as usize], g.cell_index([2, 1]));
        // Both particles' cells were surface cells (bound [0, 1]); empty cells too.
        assert!(a.lower.iter().all(|&l| l == 0) && a.upper.iter().all(|&u| u == 1));
    }

    #[test]
    fn inner_cells_keep_their_count_as_lower_bound_3d() {
        let g = Grid::new([3, 3, 3]);
        let x_bar: Vec<_> = (0..27).map(|c| g.center(g.cell_coords(c))).collect();
        let solid = vec![false; 27];
        let prev = Markings::compute(&g, &x_bar, &solid);
        let p = build(
            &g,
            &x_bar,
            &x_bar,
            &prev,
            &solid,
            2,
            Directions::VonNeumann,
            None,
            None,
        )
        .unwrap();
        // A full closed box has no surface: every cell is inner with one particle.
        assert!(p.assignment.lower.iter().all(|&l| l == 1));
        assert!(p.assignment.upper.iter().all(|&u| u == 2));
        let bad = vec![Vector::<3>::new(f64::NAN, 0.5, 0.5); 27];
        assert_eq!(
            build(
                &g,
                &x_bar,
                &bad,
                &prev,
                &solid,
                2,
                Directions::VonNeumann,
                None,
                None
            )
            .unwrap_err()
            .particle,
            0
        );
    }
}
