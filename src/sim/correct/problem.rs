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

use crate::grid::{Cell, Grid, Vector};
use crate::sim::advect::CELL_MARGIN;
use crate::sim::markings::{CellKind, DepthLevel, Markings};
use crate::solvers::min_cost_flow::BoundedAssignment;
use rayon::prelude::*;

/// The candidate moves of a particle (sec. grid_move).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Directions {
    /// Stay, or one cell along an axis: 5 in 2D, 7 in 3D (the paper's choice).
    VonNeumann,
    /// Stay, or to any cell of the Moore neighbourhood: 9 in 2D, 27 in 3D.
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
#[derive(Clone, Debug, PartialEq)]
pub struct BuildError {
    pub particle: usize,
    pub reason: String,
}

impl std::fmt::Display for BuildError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "particle {}: {}", self.particle, self.reason)
    }
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

const DROPPED: u32 = u32::MAX;

/// Builds eq. problem3 from the previous positions `x_bar`, the advected positions `x_hat`, the
/// previous markings (with counts `|gamma_bar_c|`) and the current solid cells, with the band's
/// bounds and in/out signs when `band_r` is given. With `penalty` (per cell, > 0 on the cells
/// an obstacle wants, `C_new_solid`) a candidate there costs the penalty instead of its
/// distance: `sigma_solid_obj` of eq. solid_penalty2. `x_bar` is always feasible.
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
    let offsets = directions.offsets::<D>();
    let m = offsets.len();
    // In parallel: every particle's candidate cells (DROPPED outside the domain or in a solid)
    // and costs, in slots of `m`; the stay move is slot 0.
    let mut slot_cell = vec![DROPPED; x_bar.len() * m];
    let mut slot_cost = vec![0.0; x_bar.len() * m];
    slot_cell
        .par_chunks_mut(m)
        .zip(slot_cost.par_chunks_mut(m))
        .zip(x_bar.par_iter().zip(x_hat))
        .enumerate()
        .try_for_each(|(j, ((cells, costs), (xb, xh)))| {
            let err = |reason: String| BuildError {
                particle: j,
                reason,
            };
            if !xh.iter().all(|v| v.is_finite()) {
                return Err(err(format!(
                    "advected position {:?} is not finite",
                    xh.as_slice()
                )));
            }
            let Some(home) = grid.cell_of(xb) else {
                return Err(err(format!(
                    "previous position {:?} is outside the domain",
                    xb.as_slice()
                )));
            };
            if !grid.contains(xh) {
                return Err(err(format!(
                    "advected position {:?} is outside the domain",
                    xh.as_slice()
                )));
            }
            for (i, o) in offsets.iter().enumerate() {
                let Some(c) = offset_cell(grid, home, o) else {
                    continue;
                };
                let ci = grid.cell_index(c);
                if !solid[ci] {
                    cells[i] = ci as u32;
                    costs[i] = match penalty.map(|p| p[ci]) {
                        Some(p) if p > 0.0 => p,
                        _ => (grid.closest_in_cell(xh, c, CELL_MARGIN) - xh).norm_squared(),
                    };
                }
            }
            if cells[0] == DROPPED {
                return Err(err(format!("its previous cell {home:?} is solid")));
            }
            Ok(())
        })?;
    // In order: number the cells that candidates reach and pack the candidates.
    let mut bin_of_cell = vec![u32::MAX; grid.num_cells()];
    let mut p = CorrectionProblem {
        assignment: BoundedAssignment {
            item_start: Vec::with_capacity(x_bar.len() + 1),
            cand_bin: Vec::with_capacity(slot_cell.len()),
            cand_cost: Vec::with_capacity(slot_cell.len()),
            ..Default::default()
        },
        bin_cell: vec![],
        stay: Vec::with_capacity(x_bar.len()),
        band_sign: vec![],
    };
    let a = &mut p.assignment;
    let low = |c: u32| band_r.is_some_and(|r| previous.at_or_below_interface(c as usize, r));
    a.item_start.push(0);
    for (cells, costs) in slot_cell.chunks(m).zip(slot_cost.chunks(m)) {
        p.stay.push(a.cand_bin.len() as u32);
        let home_low = low(cells[0]);
        for (&ci, &cost) in cells.iter().zip(costs).filter(|(c, _)| **c != DROPPED) {
            if band_r.is_some() {
                p.band_sign.push(match (home_low, low(ci)) {
                    (false, true) => 1,
                    (true, false) => -1,
                    _ => 0,
                });
            }
            let ci = ci as usize;
            if bin_of_cell[ci] == u32::MAX {
                bin_of_cell[ci] = p.bin_cell.len() as u32;
                p.bin_cell.push(ci);
                let (lower, upper) = cell_bounds(previous, ci, mu, band_r);
                a.lower.push(lower);
                a.upper.push(upper);
            }
            a.cand_bin.push(bin_of_cell[ci]);
            a.cand_cost.push(cost);
        }
        a.item_start.push(a.cand_bin.len());
    }
    Ok(p)
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
