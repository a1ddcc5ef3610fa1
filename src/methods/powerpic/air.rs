//! The air occupancy baseline of the free surface (our reconstruction; see the module doc of
//! `super`): how much of each transport cell the liquid is estimated to leave empty.
//!
//! The estimate is the complement of the paper's own volume measure (Levi, eq. volume): a
//! transport cell in simulation cell `c` has the baseline `b_j = V_j (1 - V_c)`, with `V_c = 1`
//! in fluid cells deeper than one cell below the surface, `min(1, |gamma_c| / mu)` in the
//! surface layer (depth 0 and -1), and 0 outside the liquid. Deep cells must therefore be full
//! even where the particles have drifted apart, which pulls them back together; a sparse
//! surface cell is expected to be partly air.

use crate::stages::markings::Markings;
use crate::stages::volume::cell_volume;

/// `b_j` of a free transport cell of volume `v_j` in simulation cell `c`, from the markings of
/// the simulation grid at `mu` particles per cell.
pub fn air_baseline(v_j: f64, markings: &Markings, mu: u32, c: usize) -> f64 {
    v_j * (1.0 - cell_volume(markings, mu, c))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Grid, Vector};
    use crate::solvers::sinkhorn::TransportGrid;

    #[test]
    fn the_baseline_is_zero_deep_inside_the_liquid_and_the_cell_volume_far_outside_2d_and_3d() {
        // A block of 2^d particles per cell on a regular lattice filling the cells [0, 6)
        // along every axis of a 12-cell grid, one particle taken out of the top corner cell;
        // transport cells of side 1/2.
        fn check<const D: usize>() {
            let grid = Grid::new([12; D]);
            let mut points: Vec<Vector<D>> = (0..12usize.pow(D as u32))
                .map(|mut i| {
                    Vector::<D>::from_fn(|_, _| {
                        let at = i % 12;
                        i /= 12;
                        (at as f64 + 0.5) * 0.5
                    })
                })
                .collect();
            points.pop();
            let markings = Markings::compute(&grid, &points, &vec![false; grid.num_cells()]);
            let fine = Grid::new([24; D]);
            let cell = 0.5f64.powi(D as i32);
            let tg = TransportGrid::new(fine, 0.5);
            let mu = 2u32.pow(D as u32);
            for j in 0..tg.grid.num_cells() {
                let x = tg.center(j);
                let b = air_baseline(cell, &markings, mu, grid.cell_index_of(&x));
                let expected = match x.iter().fold(0.0f64, |m, &v| m.max(v)) {
                    m if m < 4.0 => 0.0,
                    m if m > 7.0 => cell,
                    _ if x.iter().all(|&v| v > 5.0 && v < 6.0) => cell / mu as f64,
                    _ => continue,
                };
                assert!((b - expected).abs() < 1e-15, "{D}D, cell at {x:?}: {b}");
            }
        }
        check::<2>();
        check::<3>();
    }
}
