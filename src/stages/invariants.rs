//! The invariants every method keeps, checked after every step (`crate::step`): the
//! particles (count, finite, inside the domain, outside solids) and the speed bound of the
//! transfer to the particles; a broken one is an [`InvariantViolation`].

use crate::grid::{Grid, Vector};
use crate::PAR_GRAIN;
use rayon::prelude::*;

/// A broken invariant: a bug, reported with what and where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invariant broken: {0}")]
pub struct InvariantViolation(pub String);

/// Checks the invariants every method keeps, in O(particles): the particle count equals
/// `expected_count`, every position and velocity is finite and inside the domain, and no
/// particle sits in a solid cell.
pub fn check_particles<const D: usize>(
    grid: &Grid<D>,
    pos: &[Vector<D>],
    vel: &[Vector<D>],
    solid: &[bool],
    expected_count: usize,
) -> Result<(), InvariantViolation> {
    if pos.len() != expected_count || vel.len() != expected_count {
        return Err(InvariantViolation(format!(
            "particle count {} (velocities {}) differs from the {} seeded or emitted",
            pos.len(),
            vel.len(),
            expected_count
        )));
    }
    for (j, (x, v)) in pos.iter().zip(vel).enumerate() {
        if !x.iter().all(|c| c.is_finite()) || !v.iter().all(|c| c.is_finite()) {
            return Err(InvariantViolation(format!(
                "particle {j} is not finite: x = {:?}, v = {:?}",
                x.as_slice(),
                v.as_slice()
            )));
        }
        match grid.cell_of(x) {
            None => {
                return Err(InvariantViolation(format!(
                    "particle {j} left the domain: x = {:?}",
                    x.as_slice()
                )))
            }
            Some(c) if solid[grid.cell_index(c)] => {
                return Err(InvariantViolation(format!(
                    "particle {j} is inside solid cell {c:?}"
                )))
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// Checks the speed bound that every method's transfer to the particles applies
/// ([`crate::stages::transfer::limit_speeds`]): no particle faster than `max_speed` (cells per
/// second), up to the rounding of scaling a faster velocity down to it (a relative
/// [`SPEED_BOUND_ROUNDING`]).
pub fn check_speed_bound<const D: usize>(
    vel: &[Vector<D>],
    max_speed: f64,
) -> Result<(), InvariantViolation> {
    let limit = max_speed * (1.0 + SPEED_BOUND_ROUNDING);
    let too_fast = |v: &Vector<D>| v.norm_squared() > limit * limit;
    match (vel.par_iter().with_min_len(PAR_GRAIN)).position_first(too_fast) {
        None => Ok(()),
        Some(j) => Err(InvariantViolation(format!(
            "particle {j} moves at {} cells/s after the transfer to particles, above the bound \
             max_speed = {max_speed}",
            vel[j].norm()
        ))),
    }
}

/// The relative rounding allowed above `max_speed` by [`check_speed_bound`]: `v * (max / |v|)`
/// takes a few roundings (the norm, the quotient, the products), each of 2^-53 relative.
const SPEED_BOUND_ROUNDING: f64 = 1e-12;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speed_bound_check_passes_bounded_speeds_and_names_a_faster_particle() {
        fn check<const D: usize>(rng: &mut rand::rngs::StdRng) {
            use rand::Rng;
            let max_speed = 7.5;
            // Speeds up to ten times the bound, many just around it, then bounded by the
            // transfer's own scaling.
            let mut vel: Vec<Vector<D>> = (0..20_000)
                .map(|j| {
                    let dir = Vector::<D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
                    let speed = if j % 2 == 0 {
                        max_speed * (1.0 + rng.random_range(-1e-9..1e-9))
                    } else {
                        rng.random_range(0.0..10.0 * max_speed)
                    };
                    dir.normalize() * speed
                })
                .collect();
            crate::stages::transfer::limit_speeds(&mut vel, max_speed);
            assert_eq!(check_speed_bound(&vel, max_speed), Ok(()));
            vel[1234] = vel[1234].normalize() * (max_speed * (1.0 + 1e-9));
            let err = check_speed_bound(&vel, max_speed).unwrap_err();
            assert!(err.0.starts_with("particle 1234 "), "{err}");
        }
        let mut rng = <rand::rngs::StdRng as rand::SeedableRng>::seed_from_u64(5);
        check::<2>(&mut rng);
        check::<3>(&mut rng);
    }

    #[test]
    fn invariants_catch_solid_and_nan() {
        let g = Grid::new([4, 4, 4]);
        let mut solid = vec![false; 64];
        solid[g.cell_index([1, 1, 1])] = true;
        let ok = vec![Vector::<3>::new(0.5, 0.5, 0.5)];
        let z = vec![Vector::<3>::zeros()];
        assert!(check_particles(&g, &ok, &z, &solid, 1).is_ok());
        assert!(check_particles(&g, &ok, &z, &solid, 2).is_err());
        let bad = vec![Vector::<3>::new(1.5, 1.5, 1.5)];
        assert!(check_particles(&g, &bad, &z, &solid, 1).is_err());
        let nan = vec![Vector::<3>::new(f64::NAN, 0.5, 0.5)];
        assert!(check_particles(&g, &nan, &z, &solid, 1).is_err());
    }
}
