//! Emitters (paper sec. 8, the breaking dam): a box that injects particles at a given velocity
//! over a time interval, until a total particle count is reached.

use crate::grid::{Grid, Vector};
use crate::particles::{stratified_samples, Particles, Region};
use crate::stages::State;
use rand::Rng;

/// The emission stage: every emitter that emits now tops up its cells to `mu` (by `count`, the
/// particle count of a cell the method says emitters see, asked for those cells alone, before
/// any is added), and the particle total and `V*` grow with what was added. Returns how many
/// particles were added.
pub fn emit<const D: usize>(s: &mut State<D>, count: impl Fn(&State<D>, usize) -> u32) -> usize {
    let counts: Vec<Option<Vec<u32>>> = (s.config.emitters.iter())
        .map(|e| {
            e.emits_at(s.time_secs)
                .then(|| e.region.cells(&s.grid).map(|c| count(s, c)).collect())
        })
        .collect();
    let c = &s.config;
    let mut added = 0;
    for (e, counts) in c.emitters.iter().zip(&counts) {
        let Some(counts) = counts else { continue };
        added += e.emit(
            &s.grid,
            counts,
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
    /// Whether it emits at time `time_secs`: from `start_secs` until before `stop_secs`.
    pub fn emits_at(&self, time_secs: f64) -> bool {
        (self.start_secs..self.stop_secs).contains(&time_secs)
    }

    /// Tops up the emitter's non-solid cells to `mu` particles each (jittered sub-cell
    /// samples; `count` holds their particle counts, in the order of its region's cells),
    /// without the particles ever seeded or emitted (`total`, held or not) exceeding
    /// `until_particles`. Returns how many were added.
    #[allow(clippy::too_many_arguments)]
    pub fn emit(
        &self,
        grid: &Grid<D>,
        count: &[u32],
        total: usize,
        solid: &[bool],
        per_axis: usize,
        jitter: f64,
        particles: &mut Particles<D>,
        rng: &mut impl Rng,
    ) -> usize {
        let mu = per_axis.pow(D as u32);
        let mut room = self
            .until_particles
            .map_or(usize::MAX, |n| n.saturating_sub(total));
        let mut added = 0;
        for (c, &n) in self.region.cells(grid).zip(count) {
            if room == 0 {
                break;
            }
            if solid[c] || n as usize >= mu {
                continue;
            }
            let want = (mu - n as usize).min(room);
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
