//! Particle advection (paper alg. flip, line 5): `x_hat = x_bar + dt u(x_bar)`, forward Euler
//! on the projected grid velocity, as in the author's MantaFlow driver; and, for the band
//! method, semi-Lagrangian advection of the grid velocity (alg. band, line 5; Stam 1999).
//!
//! Each velocity component at a particle is a convex combination of face values, so with
//! `dt * max|u_face| <= 1` no particle moves more than one cell along any axis: it stays in the
//! Moore neighbourhood of its cell (sec. grid_move).

use crate::grid::active::Active;
use crate::grid::{AtGridPoints, Grid, MacField, NearCells, Vector};
use rayon::prelude::*;

/// The margin epsilon of eq. best_cell_pos, in cells.
pub const CELL_MARGIN: f64 = 0.01;

/// Moves every particle with the grid velocity ([`displace`] by `dt u(x)`); `at` is `u(x)` per
/// particle when the transfer back to the particles already has it.
pub fn advect_particles<const D: usize>(
    grid: &Grid<D>,
    u: &MacField<D>,
    at: Option<&[Vector<D>]>,
    solid: &[bool],
    dt: f64,
    pos: &mut [Vector<D>],
) {
    let pos = pos.par_iter_mut().with_min_len(crate::PAR_GRAIN_PARTICLES);
    match at {
        Some(at) => pos
            .zip(at)
            .for_each(|(x, v)| *x = displace(grid, solid, x, dt * v)),
        None => pos.for_each(|x| *x = displace(grid, solid, x, dt * u.interpolate(grid, x))),
    }
}

/// Where a particle at `x` ends when moved by `d`: clamped into the domain, `CELL_MARGIN` from
/// its walls; and if that is in a cell flagged in `solid`, it stays in its own cell at the point
/// closest to where it was heading.
pub fn displace<const D: usize>(
    grid: &Grid<D>,
    solid: &[bool],
    x: &Vector<D>,
    d: Vector<D>,
) -> Vector<D> {
    let from = grid.cell_of(x).expect("particle inside the domain");
    let mut to = *x + d;
    for k in 0..D {
        to[k] = to[k].clamp(CELL_MARGIN, grid.dims[k] as f64 - CELL_MARGIN);
    }
    if solid[grid.cell_index_of(&to)] {
        to = grid.closest_in_cell(&to, from, CELL_MARGIN);
    }
    to
}

/// Semi-Lagrangian advection of the grid velocity by itself over `dt` (first order): each face
/// takes the value found at the point its velocity traces back from, `u(x_f - dt u(x_f))`.
/// Only faces next to a cell of `needed` are advected; the other `active` faces keep `u`, the
/// rest are zero (the band method reads the grid velocity only near its interface and deep).
pub fn advect_velocity<const D: usize>(
    grid: &Grid<D>,
    u: &MacField<D>,
    dt: f64,
    needed: &NearCells,
    active: &Active<D>,
) -> MacField<D> {
    let mut out = active.copy(u);
    for (a, comp) in out.comp.iter_mut().enumerate() {
        let at_faces = AtGridPoints::faces(grid, a);
        grid.par_for_each_face_near(a, comp, needed, |_, f, v| {
            let x = grid.face_point(a, f);
            let mut back = x - dt * at_faces.interpolate(grid, u, f);
            for k in 0..D {
                back[k] = back[k].clamp(0.0, grid.dims[k] as f64);
            }
            *v = u.interpolate_component(grid, a, &back);
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn semi_lagrangian_keeps_uniform_flow_and_transports_a_linear_profile_3d() {
        let g = Grid::new([8, 6, 5]);
        let mut u = MacField::zeros(&g);
        u.comp[0].iter_mut().for_each(|v| *v = 2.0);
        // v = 0.5 * x varies along x; advected by u = 2 for dt = 0.5 it shifts by one cell:
        // v_new(x) = 0.5 * (x - 1), away from the inflow wall.
        for i in 0..g.num_faces(1) {
            let f = g.face_coords(1, i);
            u.comp[1][i] = 0.5 * (f[0] as f64 + 0.5);
        }
        let all = NearCells::new(&g, vec![true; g.num_cells()]);
        let out = advect_velocity(&g, &u, 0.5, &all, &Active::all(&g));
        assert!(out.comp[0].iter().all(|&v| (v - 2.0).abs() < 1e-12));
        for i in 0..g.num_faces(1) {
            let f = g.face_coords(1, i);
            let x = f[0] as f64 + 0.5;
            if x > 1.5 {
                assert!((out.comp[1][i] - 0.5 * (x - 1.0)).abs() < 1e-12);
            }
        }
    }

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
        let at: Vec<_> = pos.iter().map(|x| u.interpolate(&g, x)).collect();
        let mut pos2 = pos.clone();
        advect_particles(&g, &u, Some(&at), &solid, 0.25, &mut pos2);
        advect_particles(&g, &u, None, &solid, 0.25, &mut pos);
        assert_eq!(pos, pos2);
        assert!((pos[0] - Vector::<3>::new(2.0, 1.5, 1.5)).norm() < 1e-12);
        assert_eq!(pos[1][0], 8.0 - CELL_MARGIN);
        assert_eq!(pos[2], Vector::<3>::new(5.0 - CELL_MARGIN, 2.5, 2.5));
    }
}
