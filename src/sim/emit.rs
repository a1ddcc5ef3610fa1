//! Emitters (paper sec. 8, the breaking dam): a box that injects particles at a given velocity
//! over a time interval, until a total particle count is reached.

use crate::grid::{Grid, Vector};
use crate::particles::{stratified_samples, Particles, Region};
use crate::sim::State;
use rand::Rng;

/// The emission stage: every emitter tops up its cells to `mu` (by `counts`, the particle
/// count per cell the method says emitters see, or the markings' when it gives `None`; asked
/// only when there are emitters), and the particle total and `V*` grow with what was added.
/// Returns how many particles were added.
pub fn emit<const D: usize>(
    s: &mut State<D>,
    counts: impl FnOnce(&State<D>) -> Option<Vec<u32>>,
) -> usize {
    if s.config.emitters.is_empty() {
        return 0;
    }
    let counts = counts(s);
    let count = counts.as_deref().unwrap_or(&s.markings.count);
    let c = &s.config;
    let mut added = 0;
    for e in &c.emitters {
        added += e.emit(
            &s.grid,
            s.time_secs,
            count,
            s.total_particles + added,
            &s.solids.solid,
            c.per_axis,
            c.jitter,
            &mut s.particles,
            &mut s.rng,
        );
    }
    s.total_particles += added;
    s.target_volume += added as f64 / c.mu() as f64;
    added
}

/// An emitter in grid units.
#[derive(Clone, Debug, PartialEq)]
pub struct Emitter<const D: usize> {
    pub region: Region<D>,
    /// Velocity of emitted particles, cells per second.
    pub velocity: Vector<D>,
    pub start_secs: f64,
    pub stop_secs: f64,
    /// Stop once the scene holds this many particles.
    pub until_particles: Option<usize>,
}

impl<const D: usize> Emitter<D> {
    /// Tops up the emitter's non-solid cells to `mu` particles each (jittered sub-cell
    /// samples), without the particles ever seeded or emitted (`total`, held or not) exceeding
    /// `until_particles`. Returns how many were added.
    #[allow(clippy::too_many_arguments)]
    pub fn emit(
        &self,
        grid: &Grid<D>,
        time_secs: f64,
        count: &[u32],
        total: usize,
        solid: &[bool],
        per_axis: usize,
        jitter: f64,
        particles: &mut Particles<D>,
        rng: &mut impl Rng,
    ) -> usize {
        if time_secs < self.start_secs || time_secs >= self.stop_secs {
            return 0;
        }
        let mu = per_axis.pow(D as u32);
        let mut room = self
            .until_particles
            .map_or(usize::MAX, |n| n.saturating_sub(total));
        let mut added = 0;
        for c in self.region.cells(grid) {
            if room == 0 {
                break;
            }
            if solid[c] || count[c] as usize >= mu {
                continue;
            }
            let want = (mu - count[c] as usize).min(room);
            let samples = stratified_samples(grid.cell_coords(c), per_axis, jitter, rng);
            for x in samples.into_iter().take(want) {
                particles.push(x, self.velocity);
            }
            room -= want;
            added += want;
        }
        added
    }
}
