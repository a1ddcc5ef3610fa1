//! The time step (paper sec. grid_move): small enough that no particle and no obstacle moves
//! more than `cfl <= 1` cells along any axis in one step.

use crate::grid::active::Active;
use crate::grid::{nan_max, Grid, MacField, Vector};
use crate::solvers::pcg::PcgStats;
use crate::stages::invariants::InvariantViolation;
use crate::stages::State;

/// The time step for the coming step: at most `max_dt`, and small enough that the current
/// particle speed plus one step of gravity moves nothing more than `cfl` cells:
/// `(v + g dt) dt <= cfl`. The projection can still raise the speed; [`shortened`] then
/// shortens the step.
pub fn planned<const D: usize>(s: &State<D>) -> f64 {
    let c = &s.config;
    let v = s
        .particles
        .vel
        .iter()
        .map(|v| v.amax())
        .fold(0.0f64, f64::max)
        .min(c.max_speed)
        .max(
            s.solids
                .obstacles
                .iter()
                .map(|o| o.velocity.amax())
                .fold(0.0, f64::max),
        );
    let g = c.gravity.amax();
    let dt = if g > 0.0 {
        (-v + (v * v + 4.0 * g * c.cfl).sqrt()) / (2.0 * g)
    } else if v > 0.0 {
        c.cfl / v
    } else {
        f64::INFINITY
    };
    dt.min(c.max_dt_secs)
}

/// The largest face velocity component after the projection, cells per second: over the
/// `active` faces, and `air` (the velocity of the faces off the active set,
/// [`crate::stages::forces::air_velocity`]) in each component that has such faces; an error if
/// the field is not finite.
pub fn finite_speed<const D: usize>(
    grid: &Grid<D>,
    u: &MacField<D>,
    active: &Active<D>,
    air: Vector<D>,
    pcg: &PcgStats,
) -> Result<f64, InvariantViolation> {
    let has_air = |a: usize| active.num_faces(a) < grid.num_faces(a);
    let air = (0..D)
        .filter(|&a| has_air(a))
        .fold(0.0, |m, a| air[a].abs().max(m));
    let v = nan_max(active.max_abs(u), air);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(InvariantViolation(format!(
            "the grid velocity is not finite after the pressure solve ({pcg:?})"
        )))
    }
}

/// `dt`, shortened if the projected field at `max_speed` would move anything more than `cfl`
/// cells; and whether it was.
pub fn shortened(dt: f64, max_speed: f64, cfl: f64) -> (f64, bool) {
    if max_speed * dt > cfl {
        (cfl / max_speed, true)
    } else {
        (dt, false)
    }
}
