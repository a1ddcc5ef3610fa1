//! Body forces and the solid boundary condition (paper alg. flip line 2, eq. solid_boundary):
//! gravity on every active face, then every active face on the domain boundary or next to a
//! solid cell takes the solid's normal velocity.

use crate::grid::active::par_runs;
use crate::grid::{MacField, Vector};
use crate::stages::{pressure, SimConfig, State};
use rayon::prelude::*;

/// Adds `g dt` to the grid velocity on the active faces and applies the solid boundary
/// condition there.
pub fn apply<const D: usize>(s: &State<D>, u: &mut MacField<D>, dt: f64) {
    for a in 0..D {
        let g = s.config.gravity[a] * dt;
        if g != 0.0 {
            par_runs(s.active.faces(a), &mut u.comp[a])
                .for_each(|(_, run)| run.iter_mut().for_each(|v| *v += g));
        }
    }
    pressure::apply_solid_boundary(&s.grid, (&s.solids).into(), u, &s.active);
}

/// The velocity of the air far from the liquid after a step's forces and projection: zero
/// from the particles, plus `g dt`, within the speed bound. It is what a face off the active
/// set would hold had the forces visited it (no particle, wall, projection or extrapolation
/// reaches it), and counts in the step's largest speed wherever such faces exist.
pub fn air_velocity<const D: usize>(c: &SimConfig<D>, dt: f64) -> Vector<D> {
    (c.gravity * dt).map(|v| v.clamp(-c.max_speed, c.max_speed))
}
