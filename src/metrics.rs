//! What is measured of a run: how the liquid moves (the same measure for every method),
//! medians, and the time of each stage of the step. (The volume measure of eq. volume and the
//! invariants are the stages', `crate::stages::volume` and `crate::stages::invariants`.)

use crate::grid::active::Active;
use crate::grid::{Grid, MacField, Vector};
use std::time::Duration;

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
}
