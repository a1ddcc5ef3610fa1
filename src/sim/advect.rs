//! Particle advection (paper alg. flip, line 5): `x_hat = x_bar + dt u(x_bar)`, forward Euler
//! on the projected grid velocity, as in the author's MantaFlow driver.
//!
//! Each velocity component at a particle is a convex combination of face values, so with
//! `dt * max|u_face| <= 1` no particle moves more than one cell along any axis: it stays in the
//! Moore neighbourhood of its cell (sec. grid_move).

use crate::grid::{Grid, MacField, Vector};
use rayon::prelude::*;

/// The margin epsilon of eq. best_cell_pos, in cells.
pub const CELL_MARGIN: f64 = 0.01;

/// Moves every particle with the grid velocity. A particle that would leave the domain is
/// clamped inside it; one that would enter a solid cell stays in its own cell, at the point
/// closest to where it was heading.
pub fn advect_particles<const D: usize>(
    grid: &Grid<D>,
    u: &MacField<D>,
    solid: &[bool],
    dt: f64,
    pos: &mut [Vector<D>],
) {
    pos.par_iter_mut().for_each(|x| {
        let from = grid.cell_of(x).expect("particle inside the domain");
        let mut to = *x + dt * u.interpolate(grid, x);
        for k in 0..D {
            to[k] = to[k].clamp(CELL_MARGIN, grid.dims[k] as f64 - CELL_MARGIN);
        }
        if solid[grid.cell_index_of(&to)] {
            to = grid.closest_in_cell(&to, from, CELL_MARGIN);
        }
        *x = to;
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_flow_translates_and_walls_stop_particles() {
        let g = Grid::new([8, 8, 8]);
        let mut u = MacField::zeros(&g);
        u.comp[0].iter_mut().for_each(|v| *v = 2.0);
        let mut solid = vec![false; g.num_cells()];
        solid[g.cell_index([5, 2, 2])] = true;
        let mut pos = vec![
            Vector::<3>::new(1.5, 1.5, 1.5),
            Vector::<3>::new(7.8, 1.5, 1.5),
            Vector::<3>::new(4.6, 2.5, 2.5),
        ];
        advect_particles(&g, &u, &solid, 0.25, &mut pos);
        assert!((pos[0] - Vector::<3>::new(2.0, 1.5, 1.5)).norm() < 1e-12);
        assert_eq!(pos[1][0], 8.0 - CELL_MARGIN);
        assert_eq!(pos[2], Vector::<3>::new(5.0 - CELL_MARGIN, 2.5, 2.5));
    }
}
