//! What the state every method shares carries from one step to the next, written to and read
//! from a checkpoint ([`crate::snapshot`]): the particles, the grid velocity the next step
//! starts from, the markings, the obstacles, the clocks and counts, and the random generator.
//! The rest (the grid, the static solids, the configuration) is rebuilt from the scene.

use super::markings::{CellKind, Markings};
use super::{SimConfig, SimRng, State};
use crate::grid::{Grid, MacField};
use crate::snapshot::{Reader, SnapshotError, Writer};
use rand::SeedableRng;

/// The cell kinds by the number a checkpoint stores ([`CellKind`] as `u8`).
const KINDS: [CellKind; 3] = [CellKind::Empty, CellKind::Fluid, CellKind::Solid];

impl<const D: usize> State<D> {
    /// Writes what the next step reads.
    pub fn save<'a>(&'a self, w: &mut Writer<'a>) {
        let (pos, vel) = (&self.particles.pos, &self.particles.vel);
        w.vectors("particles.pos", pos.len(), || pos.iter());
        w.vectors("particles.vel", vel.len(), || vel.iter());
        for (k, c) in self.velocity.comp.iter().enumerate() {
            w.slice(&format!("velocity.{k}"), c);
        }
        let m = &self.markings;
        let n = [m.kind.len()];
        w.array::<u8>("markings.kind", &n, bytemuck::cast_slice(&m.kind));
        w.slice("markings.count", &m.count);
        w.bools("markings.surface", &m.surface);
        // The depth of every cell, `DEPTH_NOT_FLUID` off the fluid (the markings keep only
        // the fluid's).
        w.made("markings.depth", &n, || m.depths());
        let obstacles = &self.solids.obstacles;
        let k = obstacles.len();
        w.vectors("obstacles.offset", k, || {
            obstacles.iter().map(|o| &o.offset)
        });
        w.vectors("obstacles.velocity", k, || {
            obstacles.iter().map(|o| &o.velocity)
        });
        w.scalar("time_secs", self.time_secs);
        w.scalar("steps", self.steps);
        w.scalar("total_particles", self.total_particles as u64);
        w.scalar("target_volume", self.target_volume);
        let word = self.rng.get_word_pos();
        w.owned("rng.seed", &[32], self.rng.get_seed().to_vec());
        w.scalar("rng.stream", self.rng.get_stream());
        w.owned("rng.word_pos", &[2], vec![word as u64, (word >> 64) as u64]);
    }

    /// The state a checkpoint holds, for `config` (the scene it was written from).
    pub fn restore(config: SimConfig<D>, r: &Reader) -> Result<Self, SnapshotError> {
        let grid = Grid::new(config.dims);
        let mut solids = super::solids::Solids::new(
            &grid,
            &config.solids,
            &config.obstacles,
            config.obstacle_mode,
        );
        let k = solids.obstacles.len();
        let offsets = r.vectors::<D>("obstacles.offset", Some(k))?;
        let velocities = r.vectors::<D>("obstacles.velocity", Some(k))?;
        solids.place(&grid, &offsets, &velocities);
        let pos = r.vectors::<D>("particles.pos", None)?;
        let vel = r.vectors::<D>("particles.vel", Some(pos.len()))?;
        let mut velocity = MacField::zeros(&grid);
        for (a, c) in velocity.comp.iter_mut().enumerate() {
            *c = r.slice(&format!("velocity.{a}"), Some(c.len()))?;
        }
        let markings = restore_markings(r, &grid)?;
        Ok(State {
            active: super::active_cells(&grid, &markings, &solids),
            markings,
            time_secs: r.scalar("time_secs")?,
            steps: r.scalar("steps")?,
            total_particles: r.scalar::<u64>("total_particles")? as usize,
            target_volume: r.scalar("target_volume")?,
            rng: restore_rng(r)?,
            particles: crate::particles::Particles { pos, vel },
            velocity,
            solids,
            grid,
            config,
        })
    }
}

fn restore_markings<const D: usize>(r: &Reader, grid: &Grid<D>) -> Result<Markings, SnapshotError> {
    let n = grid.num_cells();
    let kind = (r.slice::<u8>("markings.kind", Some(n))?.into_iter())
        .map(|b| KINDS.get(b as usize).copied())
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| SnapshotError::Array {
            name: "markings.kind".into(),
            reason: "a cell kind is not 0, 1 or 2".into(),
        })?;
    Ok(Markings::from_cells(
        grid,
        kind,
        r.slice("markings.count", Some(n))?,
        r.bools("markings.surface", Some(n))?,
        r.slice("markings.depth", Some(n))?,
    ))
}

/// The generator at the word of its stream where it was saved.
fn restore_rng(r: &Reader) -> Result<SimRng, SnapshotError> {
    let seed: [u8; 32] =
        (r.slice::<u8>("rng.seed", Some(32))?.try_into()).expect("32 bytes, checked");
    let word = r.slice::<u64>("rng.word_pos", Some(2))?;
    let mut rng = SimRng::from_seed(seed);
    rng.set_stream(r.scalar("rng.stream")?);
    rng.set_word_pos(word[0] as u128 | (word[1] as u128) << 64);
    Ok(rng)
}
