//! What the state every method shares carries from one step to the next, written to and read
//! from a checkpoint ([`crate::snapshot`]): the particles, the grid velocity the next step
//! starts from, the markings, the obstacles, the clocks and counts, the random generator, and
//! the last pressure solve (where the next one starts).
//! The rest (the grid, the static solids, the configuration) is rebuilt from the scene.

use super::markings::{CellKind, Markings};
use super::pressure::WarmStart;
use super::{SimConfig, SimRng, State};
use crate::grid::{Grid, MacField, Vector};
use crate::snapshot::{
    check_elements, check_indices, check_scalar, not_finite, vector_not_finite, Reader,
    SnapshotError, Writer,
};
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
        let p = &self.pressure;
        w.slice("pressure.cells", &p.cells);
        w.slice("pressure.x", &p.x);
        w.scalar("pressure.dt", p.dt);
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
        check_elements("obstacles.velocity", &velocities, vector_not_finite)?;
        check_indices("obstacles.offset", k, |i| {
            let (o, x) = (&solids.obstacles[i], &offsets[i]);
            let outside = || format!("puts '{}' outside the tank", o.name);
            vector_not_finite(x).or_else(|| (!o.inside_tank(&grid, x)).then(outside))
        })?;
        solids.place(&grid, &offsets, &velocities);
        let pos = r.vectors::<D>("particles.pos", None)?;
        check_positions(&grid, &pos, solids.particle_free())?;
        let vel = r.vectors::<D>("particles.vel", Some(pos.len()))?;
        check_elements("particles.vel", &vel, vector_not_finite)?;
        let mut velocity = MacField::zeros(&grid);
        for (a, c) in velocity.comp.iter_mut().enumerate() {
            let name = format!("velocity.{a}");
            *c = r.slice(&name, Some(c.len()))?;
            check_elements(&name, c, not_finite)?;
        }
        let markings = restore_markings(r, &grid, pos.len())?;
        Ok(State {
            active: super::active_cells(&grid, &markings, &solids),
            markings,
            time_secs: r.scalar("time_secs").and_then(|t| {
                check_scalar(
                    "time_secs",
                    t,
                    t.is_finite() && t >= 0.0,
                    "finite, at least 0",
                )
            })?,
            steps: r.scalar("steps")?,
            total_particles: r.scalar::<u64>("total_particles")? as usize,
            target_volume: r.scalar("target_volume").and_then(|v| {
                check_scalar(
                    "target_volume",
                    v,
                    v.is_finite() && v > 0.0,
                    "finite and positive",
                )
            })?,
            rng: restore_rng(r)?,
            pressure: restore_pressure(r, grid.num_cells())?,
            particles: crate::particles::Particles { pos, vel },
            velocity,
            solids,
            grid,
            config,
        })
    }
}

/// Every particle where a step leaves it: finite, inside the domain, and in no cell where
/// particles may not be (`particle_free`, the solids as the obstacle mode counts them).
fn check_positions<const D: usize>(
    grid: &Grid<D>,
    pos: &[Vector<D>],
    particle_free: &[bool],
) -> Result<(), SnapshotError> {
    check_elements("particles.pos", pos, |x| {
        let why = vector_not_finite(x);
        why.or_else(|| match grid.cell_of(x) {
            None => Some(format!("{:?} is outside the domain", x.as_slice())),
            Some(c) if particle_free[grid.cell_index(c)] => {
                Some(format!("{:?} is in solid cell {c:?}", x.as_slice()))
            }
            Some(_) => None,
        })
    })
}

/// The markings of the last step: cell kinds this program knows, particle counts in no empty
/// cell that add up to the `particles` held, and a depth of at most 0 in every fluid cell
/// (def. depth).
fn restore_markings<const D: usize>(
    r: &Reader,
    grid: &Grid<D>,
    particles: usize,
) -> Result<Markings, SnapshotError> {
    let n = grid.num_cells();
    let kinds = r.slice::<u8>("markings.kind", Some(n))?;
    let known =
        |&b: &u8| (b as usize >= KINDS.len()).then(|| format!("cell kind {b} is not 0, 1 or 2"));
    check_elements("markings.kind", &kinds, known)?;
    let kind: Vec<CellKind> = kinds.into_iter().map(|b| KINDS[b as usize]).collect();
    let count = r.slice::<u32>("markings.count", Some(n))?;
    // Particles mark a cell fluid, or lie in a solid one (an obstacle that `ignore`s them).
    check_indices("markings.count", n, |c| {
        let m = count[c];
        (m > 0 && kind[c] == CellKind::Empty).then(|| format!("{m} particles in an empty cell"))
    })?;
    let total: u64 = count.iter().map(|&m| m as u64).sum();
    if total != particles as u64 {
        return Err(SnapshotError::Array {
            name: "markings.count".into(),
            reason: format!("counts {total} particles, the checkpoint holds {particles}"),
        });
    }
    let depth = r.slice::<i32>("markings.depth", Some(n))?;
    check_indices("markings.depth", n, |c| {
        let d = depth[c];
        (kind[c] == CellKind::Fluid && d > 0)
            .then(|| format!("a fluid cell at depth {d}, above its surface (0)"))
    })?;
    let surface = r.bools("markings.surface", Some(n))?;
    Ok(Markings::from_cells(grid, kind, count, surface, depth))
}

/// The last pressure solve ([`super::pressure::WarmStart`]): its cells ascending within the
/// grid's `cells`, a finite pressure on each, a time step finite and not negative. A checkpoint
/// written before the warm start (2026-12-01) has none and is refused: its run could not go on
/// as it would have. (The format's version stays 2: the report's result files share it, and a
/// new version would have made every kept result unreadable.)
fn restore_pressure(r: &Reader, cells: usize) -> Result<WarmStart, SnapshotError> {
    if !r.has("pressure.cells") {
        return Err(SnapshotError::Array {
            name: "pressure.cells".into(),
            reason: "absent: written before the pressure solve's warm start (2026-12-01), the \
                run cannot resume bit for bit; start it again"
                .into(),
        });
    }
    let at = r.slice::<u32>("pressure.cells", None)?;
    check_indices("pressure.cells", at.len(), |i| {
        let c = at[i];
        if c as usize >= cells {
            return Some(format!("{c} is outside the grid's {cells} cells"));
        }
        let before = i.checked_sub(1).map(|j| at[j]).filter(|&b| b >= c);
        before.map(|b| format!("{c} follows {b}: not ascending"))
    })?;
    let x = r.slice::<f64>("pressure.x", Some(at.len()))?;
    check_elements("pressure.x", &x, not_finite)?;
    let dt = r.scalar("pressure.dt").and_then(|t| {
        check_scalar(
            "pressure.dt",
            t,
            t.is_finite() && t >= 0.0,
            "finite, at least 0",
        )
    })?;
    Ok(WarmStart { cells: at, x, dt })
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
