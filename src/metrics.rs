//! The volume measure of paper eq. volume, invariant checks and stage timings.

use crate::grid::active::Active;
use crate::grid::{Grid, MacField, Vector};
use crate::stages::markings::{CellKind, Markings};
use crate::PAR_GRAIN;
use rayon::prelude::*;
use std::time::Duration;

/// Total fluid volume `V = sum_c V_c` in cells (paper eq. volume), each cell's `V_c` from
/// [`cell_volume`], summed in cell order over `active`, which holds every fluid cell (the
/// others add exactly zero).
pub fn volume_cells<const D: usize>(markings: &Markings, mu: u32, active: &Active<D>) -> f64 {
    (active.each_cell()).fold(0.0, |v, c| v + cell_volume(markings, mu, c))
}

/// Cell `c`'s fluid volume `V_c` in cells (paper eq. volume): 0 for non-fluid cells (depth >
/// 0), `min(1, |gamma_c| / mu)` for cells at depth -1 or 0, and 1 for deeper fluid cells.
/// Solid cells count as pure solid, whatever they hold.
pub fn cell_volume(markings: &Markings, mu: u32, c: usize) -> f64 {
    if markings.kind[c] != CellKind::Fluid {
        return 0.0;
    }
    match markings.depth(c) {
        d if d >= -1 => (markings.count[c] as f64 / mu as f64).min(1.0),
        _ => 1.0,
    }
}

/// How the liquid moves, the same measure for every method: its kinetic energy per unit mass
/// (m^2/s^2) and its top speed (m/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LiquidMotion {
    pub kinetic_energy: f64,
    pub top_speed: f64,
}

/// [`LiquidMotion`] of the particles held and of the deep (`deep`: fluid cells the grid
/// carries without particles, below the band of ccp's band method or of nbflip), in metres
/// (`h`: the cell size in metres; velocities are in cells per second). A particle is `1 / mu`
/// of a cell of liquid, a deep cell a whole one moving with `u` at its centre:
/// `1/2 (sum_p |v_p|^2 / mu + sum_deep |u_c|^2) / (n / mu + n_deep)`. Without a deep that is
/// `1/2 mean_p |v_p|^2`, computed as such.
pub fn liquid_motion<const D: usize>(
    grid: &Grid<D>,
    vel: &[Vector<D>],
    mu: u32,
    active: &Active<D>,
    u: &MacField<D>,
    deep: impl Fn(usize) -> bool,
    h: f64,
) -> LiquidMotion {
    // Sums and the largest of |v|^2, in one pass each over the particles and the deep.
    let gather = |(s, n, m): (f64, usize, f64), v: Vector<D>| {
        let v2 = v.norm_squared();
        (s + v2, n + 1, m.max(v2))
    };
    let (particles, _, fastest) = vel.iter().copied().fold((0.0, 0, 0.0), gather);
    let deep_cells = active.each_cell().filter(|&c| deep(c));
    let at_centres = deep_cells.map(|c| u.interpolate(grid, &grid.center(grid.cell_coords(c))));
    let (cells, n_deep, fastest) = at_centres.fold((0.0, 0usize, fastest), gather);
    let mean = match n_deep {
        0 => particles / vel.len().max(1) as f64,
        _ => {
            let mu = mu as f64;
            (particles / mu + cells) / (vel.len() as f64 / mu + n_deep as f64)
        }
    };
    LiquidMotion {
        kinetic_energy: 0.5 * mean * h * h,
        top_speed: fastest.sqrt() * h,
    }
}

/// The median of some values (the upper one of an even count); `None` when empty.
pub fn median<T: Copy + PartialOrd>(values: &[T]) -> Option<T> {
    let mut v = values.to_vec();
    v.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    v.get(v.len() / 2).copied()
}

/// The simulation's stages, for timings (one slot each).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Emit,
    ParticlesToGrid,
    Forces,
    Pressure,
    GridToParticles,
    Advect,
    Correct,
    Markings,
}

impl Stage {
    pub const ALL: [Stage; 8] = [
        Stage::Emit,
        Stage::ParticlesToGrid,
        Stage::Forces,
        Stage::Pressure,
        Stage::GridToParticles,
        Stage::Advect,
        Stage::Correct,
        Stage::Markings,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Emit => "emit",
            Stage::ParticlesToGrid => "p2g",
            Stage::Forces => "forces",
            Stage::Pressure => "pressure",
            Stage::GridToParticles => "g2p",
            Stage::Advect => "advect",
            Stage::Correct => "correct",
            Stage::Markings => "markings",
        }
    }
}

/// Wall time of each stage in one step.
#[derive(Clone, Copy, Debug, Default)]
pub struct StageTimes(pub [Duration; Stage::ALL.len()]);

impl StageTimes {
    pub fn get(&self, s: Stage) -> Duration {
        self.0[s as usize]
    }

    pub fn add(&mut self, s: Stage, d: Duration) {
        self.0[s as usize] += d;
    }

    pub fn total(&self) -> Duration {
        self.0.iter().sum()
    }

    /// Runs `f` and charges its wall time to `stage`.
    pub fn time<T>(&mut self, stage: Stage, f: impl FnOnce() -> T) -> T {
        let t0 = std::time::Instant::now();
        let out = f();
        self.add(stage, t0.elapsed());
        out
    }
}

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

/// Checks the speed bound that every method's grid-to-particle transfer applies
/// ([`crate::methods::FluidMethod::grid_to_particles`]): no particle faster than `max_speed`
/// (cells per second), up to the rounding of scaling a faster velocity down to it (a relative
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
    fn the_liquid_s_motion_weighs_a_particle_as_a_mu_th_of_a_deep_cell_2d_and_3d() {
        // A uniform flow of 2 cells/s along axis 0; 2 mu particles at 4 cells/s and, when
        // cells 0 and 1 are deep, two cells at 2: KE = 1/2 (2 mu 16 / mu + 2 * 4) / (2 + 2) =
        // 5 cells^2/s^2, without a deep 1/2 16 = 8; at h = 0.5 m a quarter of that.
        fn check<const D: usize>(dims: [usize; D]) {
            let (g, mu, h) = (Grid::new(dims), 2u32.pow(D as u32), 0.5);
            let mut u = MacField::zeros(&g);
            u.comp[0].iter_mut().for_each(|v| *v = 2.0);
            let fast = Vector::<D>::from_fn(|k, _| if k == 0 { 4.0 } else { 0.0 });
            let vel = vec![fast; 2 * mu as usize];
            let all = Active::all(&g);
            let with = liquid_motion(&g, &vel, mu, &all, &u, |c| c < 2, h);
            assert!(
                (with.kinetic_energy - 5.0 * h * h).abs() < 1e-12,
                "{D}D {with:?}"
            );
            assert_eq!(with.top_speed, 4.0 * h);
            let without = liquid_motion(&g, &vel, mu, &all, &u, |_| false, h);
            assert_eq!(without.kinetic_energy, 8.0 * h * h);
            let slow = vec![Vector::<D>::zeros(); 2];
            let deep_only = liquid_motion(&g, &slow, mu, &all, &u, |c| c < 2, h);
            assert!(
                (deep_only.top_speed - 2.0 * h).abs() < 1e-12,
                "{D}D {deep_only:?}"
            );
        }
        check([4, 3]);
        check([4, 3, 2]);
    }

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
    fn volume_counts_near_surface_cells_by_fill_and_deep_cells_as_full() {
        // 6x6 tank, fluid in the bottom 4 rows; one deep cell holds a single particle (a
        // bubble: counts 1), one surface cell holds 2 of mu = 4, one holds 6 (overflow: 1).
        let g = Grid::new([6, 6]);
        let mu = 4;
        let mut pos = vec![];
        for c in 0..g.num_cells() {
            let cc = g.cell_coords(c);
            if cc[1] >= 4 {
                continue;
            }
            let n = match cc {
                [0, 0] => 1,
                [2, 3] => 2,
                [3, 3] => 6,
                _ => mu,
            };
            for k in 0..n {
                pos.push(Vector::<2>::new(
                    cc[0] as f64 + 0.1 + 0.1 * k as f64,
                    cc[1] as f64 + 0.5,
                ));
            }
        }
        let m = Markings::compute(&g, &pos, &[false; 36]);
        assert_eq!(m.depth(g.cell_index([0, 0])), -3);
        let v = volume_cells(&m, mu, &Active::all(&g));
        assert!((v - (24.0 - 0.5)).abs() < 1e-12, "{v}");
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
