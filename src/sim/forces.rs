//! Body forces and the solid boundary condition (paper alg. flip line 2, eq. solid_boundary):
//! gravity on every face, then every face on the domain boundary or next to a solid cell takes
//! the solid's normal velocity.

use crate::grid::MacField;
use crate::sim::{pressure, State};

/// Adds `g dt` to the grid velocity and applies the solid boundary condition.
pub fn apply<const D: usize>(s: &State<D>, u: &mut MacField<D>, dt: f64) {
    for a in 0..D {
        let g = s.config.gravity[a] * dt;
        if g != 0.0 {
            u.comp[a].iter_mut().for_each(|v| *v += g);
        }
    }
    pressure::apply_solid_boundary(&s.grid, &s.solids.solid, &s.solids.velocity, u);
}
