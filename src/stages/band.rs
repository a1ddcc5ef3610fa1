//! The band of paper sec. band_method as geometry, for every method that keeps particles only
//! near the surface: the depth levels of a band `R + 1` cells thick (fig. band: surface, band,
//! band interface `C_-R`, deep `C_<-R`), the cells that stay fluid without particles, the
//! velocity combination of alg. band line 1 and the advection of the grid velocity of line 5.
//!
//! What the deep holds is a method's business: method ccp counts its imaginary particles in
//! `n_deep`; narrow-band FLIP keeps the deep as a level set.

use crate::grid::active::Active;
use crate::grid::{Cell, Grid, MacField, NearCells, Vector};
use crate::stages::advect;
use crate::stages::markings::{DepthLevel, Markings};
use crate::stages::transfer::Known;

/// `R` when a scene file does not say (the paper: 3, and 6 for the dam scenes).
pub const DEFAULT_BAND_R: u32 = 3;

/// The deepest band interface taken: far deeper than any grid of ours is tall, so only a typo
/// or a value at its type's extreme meets it.
pub const MAX_BAND_R: u32 = 10_000;

/// Refuses an `R` below 1 or past [`MAX_BAND_R`], with the reason.
pub fn check_band_r(r: u32) -> Result<(), BadBandDepth> {
    match (1..=MAX_BAND_R).contains(&r) {
        true => Ok(()),
        false => Err(BadBandDepth(r)),
    }
}

/// A band depth `R` no band can have.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "must be from 1 to {MAX_BAND_R} (the band interface lies R cells below the surface), got {0}"
)]
pub struct BadBandDepth(pub u32);

/// A band `R + 1` cells thick: the interface is at depth `-R`, the deep below it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Band {
    /// `R >= 1`.
    pub r: u32,
}

impl Band {
    /// The level of cell `c` (not fluid for empty and solid cells).
    pub fn level(&self, m: &Markings, c: usize) -> DepthLevel {
        if m.is_fluid(c) {
            m.level(c, self.r)
        } else {
            DepthLevel::NotFluid
        }
    }

    /// Cells that stay fluid without particles in the next markings: every fluid cell below
    /// the surface. The deep's particles are imaginary, the interface may lose all of its own,
    /// and a former deep cell can rise into the band with none (a bubble in the band): none of
    /// these may turn empty, or a hole would open inside the fluid. (Without the band, inner
    /// cells keep their particles, so this changes nothing there.) `active` holds every fluid
    /// cell of `m`.
    pub fn kept_cells<const D: usize>(
        grid: &Grid<D>,
        m: &Markings,
        active: &Active<D>,
    ) -> NearCells {
        active.near_cells(grid, |c| m.is_fluid(c) && !m.surface[c])
    }

    /// The particle count emitters see in cell `c`: deep cells hold imaginary particles, so
    /// they count as full (`mu`).
    pub fn emitter_count(&self, m: &Markings, mu: u32, c: usize) -> u32 {
        count_with_full_deep(m, mu, self.level(m, c), c)
    }

    /// A real particle in the deep, if there is one (there must be none after the exchange
    /// with the deep).
    pub fn particle_in_deep<'a, const D: usize>(
        &self,
        grid: &Grid<D>,
        m: &Markings,
        pos: &'a [Vector<D>],
    ) -> Option<&'a Vector<D>> {
        pos.iter()
            .find(|x| self.level(m, grid.cell_index_of(x)) == DepthLevel::Deep)
    }

    /// The velocity combination of alg. band line 1: faces next to a band interface or deep
    /// cell (depth `<= -R`) take the grid velocity `grid_u` and count as known; the others
    /// keep the particle velocity where particles gave weight. `active` holds every fluid
    /// cell of `m`.
    pub fn combine_with_grid<const D: usize>(
        &self,
        grid: &Grid<D>,
        u: &mut MacField<D>,
        known: &mut Known<D>,
        grid_u: &MacField<D>,
        m: &Markings,
        active: &Active<D>,
    ) {
        let near = active.near_cells(grid, |c| m.at_or_below_interface(c, self.r));
        combine_velocities(grid, u, known, grid_u, &near, |_, _, _| true);
    }

    /// Alg. band line 5: the grid velocity advected semi-Lagrangian over `dt`. The next step
    /// reads it next to the interface and the deep, which lie inside the fluid: the faces of
    /// fluid cells are advected, the others keep `u`. `active` holds every fluid cell of `m`.
    pub fn advect_grid_velocity<const D: usize>(
        grid: &Grid<D>,
        u: &MacField<D>,
        dt: f64,
        m: &Markings,
        active: &Active<D>,
    ) -> MacField<D> {
        let fluid = active.near_cells(grid, |c| m.is_fluid(c));
        advect::advect_velocity(grid, u, dt, &fluid, active)
    }
}

/// The markings' particle count of cell `c`, or full (`mu`) if its `level` is deep: what
/// emitters see under a band method, whose deep holds no particles.
pub fn count_with_full_deep(m: &Markings, mu: u32, level: DepthLevel, c: usize) -> u32 {
    match level {
        DepthLevel::Deep => mu,
        _ => m.count[c],
    }
}

/// The velocity combination of the band methods (paper alg. band line 1; Ferstl et al. 2016,
/// sec. 4): faces next to a cell of `near` for which `take_grid(axis, face_coords,
/// had_particle_weight)` holds take the grid velocity `grid_u` and count as known; the others
/// keep the particles' velocity `u` where particles gave weight. (Coordinates, not indices: a
/// pass over faces must not divide; only the lines of faces beside a flagged cell are walked.)
pub fn combine_velocities<const D: usize>(
    grid: &Grid<D>,
    u: &mut MacField<D>,
    known: &mut Known<D>,
    grid_u: &MacField<D>,
    near: &NearCells,
    take_grid: impl Fn(usize, Cell<D>, bool) -> bool + Sync,
) {
    for (a, (u, known)) in u.comp.iter_mut().zip(known.iter_mut()).enumerate() {
        grid.par_for_each_face_pair_near(a, u, known, near, |i, f, v, k| {
            if take_grid(a, f, *k) {
                *v = grid_u.comp[a][i];
                *k = true;
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::transfer::particles_to_grid;

    #[test]
    fn band_faces_take_particles_and_faces_at_the_interface_take_the_grid_3d() {
        // A full 4x4x6 column (the tank's whole footprint) at 1 ppc, R = 1: the top layer
        // z = 5 is surface, z = 4 the interface, z <= 3 deep. Particles move at +1 along z, the
        // grid at -7.
        let g = Grid::new([4, 4, 8]);
        let mut pos = vec![];
        for c in 0..g.num_cells() {
            let cc = g.cell_coords(c);
            if cc[2] < 6 {
                pos.push(g.center(cc));
            }
        }
        let vel = vec![Vector::<3>::new(0.0, 0.0, 1.0); pos.len()];
        let m = Markings::compute(&g, &pos, &vec![false; g.num_cells()]);
        let (mut u, mut known) = particles_to_grid(&g, &pos, &vel);
        let mut grid_u = MacField::zeros(&g);
        grid_u.comp[2].iter_mut().for_each(|v| *v = -7.0);
        let all = Active::all(&g);
        Band { r: 1 }.combine_with_grid(&g, &mut u, &mut known, &grid_u, &m, &all);
        for i in 0..g.num_faces(2) {
            let f = g.face_coords(2, i);
            match f[2] {
                // Faces touching a cell at depth <= -1: grid velocity, known.
                0..=5 => assert!(known[2][i] && u.comp[2][i] == -7.0, "{f:?}"),
                // Between the surface layer and the air above: particle velocity.
                6 => assert!(known[2][i] && (u.comp[2][i] - 1.0).abs() < 1e-12, "{f:?}"),
                _ => assert!(!known[2][i], "{f:?}"),
            }
        }
    }
}
