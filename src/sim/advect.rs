//! Particle advection (paper alg. flip, line 5): `x_hat = x_bar + dt u(x_bar)`, forward Euler
//! on the projected grid velocity, as in the author's MantaFlow driver; and, for the band
//! method, semi-Lagrangian advection of the grid velocity (alg. band, line 5; Stam 1999).
//!
//! Each velocity component at a particle is a convex combination of face values, so with
//! `dt * max|u_face| <= 1` no particle moves more than one cell along any axis: it stays in the
//! Moore neighbourhood of its cell (sec. grid_move).

use crate::grid::{AtGridPoints, Cell, FacePoint, FaceStencil, Grid, MacField, NearCells, Vector};
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

/// The grid velocity the next step starts from ([`crate::sim::State::velocity`]): this step's
/// projected field `u`, for a band method advected by itself over `dt`, semi-Lagrangian and
/// first order (alg. band line 5; Stam 1999), on the faces next to a cell of `near` (the step's
/// fluid cells): there a face takes `u(x_f - dt u(x_f))`, elsewhere it keeps `u`.
///
/// An advected value is computed where it is read, not for every face of the liquid: the next
/// step reads it only where the combination gives a face the grid's velocity (next to the
/// deep, or without particle weight) and where particles are seeded, a small part of the
/// liquid's faces unless the liquid is deep. Each read computes the value a pass over all
/// those faces would have stored, bit for bit.
pub struct GridVelocity<const D: usize> {
    u: MacField<D>,
    advection: Option<Advection<D>>,
}

struct Advection<const D: usize> {
    dt: f64,
    near: NearCells,
    /// Per axis, the field at its faces ([`AtGridPoints::faces`]).
    at_faces: [AtGridPoints<D>; D],
}

impl<const D: usize> GridVelocity<D> {
    /// `u` as it is (no advection).
    pub fn still(u: MacField<D>) -> Self {
        Self { u, advection: None }
    }

    /// `u` advected over `dt` on the faces next to a cell of `near`.
    pub fn advected(grid: &Grid<D>, u: MacField<D>, dt: f64, near: NearCells) -> Self {
        let at_faces = std::array::from_fn(|a| AtGridPoints::faces(grid, a));
        let advection = Some(Advection { dt, near, at_faces });
        Self { u, advection }
    }

    /// The projected field, before advection.
    pub fn projected(&self) -> &MacField<D> {
        &self.u
    }

    /// The value on the face of axis `a` with index `i` and coordinates `f`.
    #[inline]
    pub fn at_face(&self, grid: &Grid<D>, a: usize, i: usize, f: Cell<D>) -> f64 {
        let (u, Some(adv)) = (&self.u, &self.advection) else {
            return self.u.comp[a][i];
        };
        if !grid.face_cells_at(a, f).any(|c| adv.near.contains(c)) {
            return u.comp[a][i];
        }
        let x = grid.face_point(a, f);
        let mut back = x - adv.dt * adv.at_faces[a].interpolate(grid, u, f);
        for k in 0..D {
            back[k] = back[k].clamp(0.0, grid.dims[k] as f64);
        }
        u.interpolate_component(grid, a, &back)
    }

    /// Multilinear interpolation at `x` ([`MacField::interpolate`] of the advected field).
    pub fn interpolate(&self, grid: &Grid<D>, x: &Vector<D>) -> Vector<D> {
        match self.advection {
            None => self.u.interpolate(grid, x),
            Some(_) => {
                let at = FacePoint::new(grid, x);
                Vector::<D>::from_fn(|a, _| {
                    let value = |i| self.at_face(grid, a, i, grid.face_coords(a, i));
                    FaceStencil::at(grid, &at, a).apply_with(value)
                })
            }
        }
    }
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
        let near = NearCells::new(&g, vec![true; g.num_cells()]);
        let out = GridVelocity::advected(&g, u, 0.5, near);
        for i in 0..g.num_faces(0) {
            let v = out.at_face(&g, 0, i, g.face_coords(0, i));
            assert!((v - 2.0).abs() < 1e-12);
        }
        for i in 0..g.num_faces(1) {
            let f = g.face_coords(1, i);
            let x = f[0] as f64 + 0.5;
            if x > 1.5 {
                assert!((out.at_face(&g, 1, i, f) - 0.5 * (x - 1.0)).abs() < 1e-12);
            }
        }
    }

    /// The advected field read between faces is the interpolation of its face values, bit for
    /// bit, 2D and 3D (the seeds of the band methods read it there); faces away from `near`
    /// keep the projected value.
    #[test]
    fn the_advected_field_between_faces_interpolates_its_face_values_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let mut u = MacField::zeros(&g);
            for (a, comp) in u.comp.iter_mut().enumerate() {
                for (i, v) in comp.iter_mut().enumerate() {
                    *v = ((i * 5 + a * 11) as f64 * 0.29).sin() * 3.0;
                }
            }
            let flags = (0..g.num_cells()).map(|c| c % 3 != 0).collect();
            let adv = GridVelocity::advected(&g, u.clone(), 0.4, NearCells::new(&g, flags));
            let mut faces = MacField::zeros(&g);
            let mut kept = 0;
            for (a, comp) in faces.comp.iter_mut().enumerate() {
                for (i, v) in comp.iter_mut().enumerate() {
                    let f = g.face_coords(a, i);
                    *v = adv.at_face(&g, a, i, f);
                    if g.face_cells_at(a, f).all(|c| c % 3 == 0) {
                        assert_eq!(v.to_bits(), u.comp[a][i].to_bits());
                        kept += 1;
                    }
                }
            }
            assert!(kept > 0 && faces != u);
            for k in 0..200 {
                let x = Vector::<D>::from_fn(|j, _| {
                    ((k * 7 + j * 3) as f64 * 0.61).sin().abs() * dims[j] as f64
                });
                let (got, want) = (adv.interpolate(&g, &x), faces.interpolate(&g, &x));
                assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "at {x}");
            }
        }
        check([7, 5]);
        check([6, 5, 4]);
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
